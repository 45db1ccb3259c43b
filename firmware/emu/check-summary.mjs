#!/usr/bin/env node
// CI's verdict on a measurement of the emulated board: prints the figures of a report's
// summary.json and fails (exit 1, saying which) unless the timing ratio is within the
// tolerance of the target and the recording has no gap, no missing sample and no CRC error.
//
//   node check-summary.mjs out/DIR/report/summary.json --ratio-tol 0.04

import * as fs from 'node:fs';
import { parseArgs } from 'node:util';

const { values, positionals } = parseArgs({
  allowPositionals: true,
  options: { 'ratio-tol': { type: 'string', default: '0.04' } },
});
if (positionals.length !== 1) {
  process.stderr.write('usage: check-summary.mjs SUMMARY.json [--ratio-tol T]\n');
  process.exit(2);
}
const path = positionals[0];
const tol = Number(values['ratio-tol']);
let s;
try {
  s = JSON.parse(fs.readFileSync(path, 'utf8'));
} catch (e) {
  process.stderr.write(`${path}: ${e.message}\n`);
  process.exit(1);
}
const h = s.headline ?? {};
const sampling = s.sampling ?? {};
const counts = s.source?.device_counts ?? {};
const fmt = (x, d) => (typeof x === 'number' ? x.toFixed(d) : String(x));
console.log(
  `emulated board, ${h.motion}: timing ratio ${fmt(h.timing_ratio_measured, 4)} ± ` +
    `${fmt(h.timing_ratio_u95, 4)} (target ${fmt(h.timing_ratio_target, 2)} ± ${tol}), ` +
    `RMS error ${fmt(h.rms_error_deg, 3)}° (max ${fmt(h.max_error_deg, 3)}°), ` +
    `${sampling.samples} samples at ${fmt(sampling.mean_rate_hz, 1)} Hz, ` +
    `${counts.gaps} gaps, ${counts.missing_samples} missing, ${counts.crc_errors} CRC errors, ` +
    `recording ${s.source?.complete ? 'complete' : `incomplete (${s.source?.end_reason})`}`,
);
const failures = [];
const measured = h.timing_ratio_measured;
const target = h.timing_ratio_target;
if (typeof measured !== 'number' || typeof target !== 'number') {
  failures.push('no timing ratio was measured');
} else if (!(Math.abs(measured - target) <= tol)) {
  failures.push(`timing ratio ${measured} is not within ${tol} of ${target}`);
}
for (const [name, value] of [
  ['gaps', counts.gaps],
  ['missing samples', counts.missing_samples],
  ['CRC errors', counts.crc_errors],
  ['sampling gaps', sampling.gaps],
]) {
  if (value !== 0) {
    failures.push(`${name}: ${value}`);
  }
}
if (s.source?.complete !== true) {
  failures.push(`the recording is incomplete (${s.source?.end_reason})`);
}
if (failures.length > 0) {
  console.log(`FAILED: ${failures.join('; ')}`);
  process.exit(1);
}
console.log('ok');
