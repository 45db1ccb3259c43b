// Validates glTF/GLB files with the Khronos glTF validator (npm `gltf-validator`, pinned in
// package.json). Usage: node validate.js FILE.glb [FILE ...]
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "hints", "messages"}
// where messages are "SEVERITY CODE at POINTER: text". Exit status: 0 when no file has an
// error, 1 when some file has one, 2 when a file cannot be read or validated at all.
'use strict';
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

const SEVERITY = ['error', 'warning', 'info', 'hint'];

async function check(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 1000,
    // A GLB written by mpc-rig is self-contained: any external reference is an error.
    externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri}`)),
  });
  const issues = report.issues;
  return {
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    hints: issues.numHints,
    messages: issues.messages.map(
      (m) => `${SEVERITY[m.severity] ?? m.severity} ${m.code} at ${m.pointer ?? '-'}: ${m.message}`,
    ),
  };
}

async function main() {
  const files = process.argv.slice(2);
  if (files.length === 0) {
    console.error('usage: node validate.js FILE.glb [FILE ...]');
    process.exit(2);
  }
  let failed = false;
  for (const file of files) {
    const result = await check(file);
    console.log(JSON.stringify(result));
    failed = failed || result.errors > 0;
  }
  process.exit(failed ? 1 : 0);
}

main().catch((e) => {
  console.error(`gltf-validate: ${e && e.stack ? e.stack : e}`);
  process.exit(2);
});
