// The pieces of the harness that do not need a firmware: descriptor parsing, the ELF loader,
// the RTT reader and the pipe's message layout.

import assert from 'node:assert/strict';
import { test } from 'node:test';

import { findSymbol, loadableSegments } from '../lib/elf.mjs';
import { parseSyncReply, timed } from '../lib/link.mjs';
import { RttReader } from '../lib/rtt.mjs';
import { findCdcAcm, parseStringDescriptor } from '../lib/usb-host.mjs';

test('string descriptors are UTF-16LE after their two header bytes', () => {
  assert.equal(parseStringDescriptor(Uint8Array.of(8, 3, 0x45, 0, 0x36, 0, 0x30, 0)), 'E60');
  assert.equal(parseStringDescriptor(Uint8Array.of(2, 3)), '');
});

test('the CDC-ACM function is found in a configuration descriptor', () => {
  // Communication interface 0 with an interrupt endpoint, data interface 1 with bulk
  // endpoints 0x82 (IN) and 0x01 (OUT), as embassy-usb lays out a CDC-ACM class.
  const config = Uint8Array.of(
    ...[9, 2, 67, 0, 2, 1, 0, 0x80, 50],
    ...[9, 4, 0, 0, 1, 0x02, 0x02, 0, 0],
    ...[7, 5, 0x83, 3, 8, 0, 255],
    ...[9, 4, 1, 0, 2, 0x0a, 0, 0, 0],
    ...[7, 5, 0x82, 2, 64, 0, 0],
    ...[7, 5, 0x01, 2, 64, 0, 0],
  );
  assert.deepEqual(findCdcAcm(config), { control: 0, in: 2, out: 1 });
});

/** A minimal ELF32 ARM executable: one PT_LOAD segment and a symbol table. */
function elf({ paddr, data, symbol, value }) {
  const strtab = Buffer.from(`\0${symbol}\0`);
  const symtab = Buffer.alloc(32);
  symtab.writeUInt32LE(1, 16); // second symbol: name at offset 1
  symtab.writeUInt32LE(value, 20);
  const ehsize = 52;
  const phoff = ehsize;
  const dataOff = phoff + 32;
  const symOff = dataOff + data.length;
  const strOff = symOff + symtab.length;
  const shoff = strOff + strtab.length;
  const b = Buffer.alloc(shoff + 3 * 40);
  Buffer.from([0x7f, 0x45, 0x4c, 0x46, 1, 1, 1]).copy(b, 0);
  b.writeUInt16LE(2, 16);
  b.writeUInt16LE(40, 18);
  b.writeUInt32LE(phoff, 28);
  b.writeUInt32LE(shoff, 32);
  b.writeUInt16LE(32, 42);
  b.writeUInt16LE(1, 44);
  b.writeUInt16LE(40, 46);
  b.writeUInt16LE(3, 48);
  b.writeUInt32LE(1, phoff); // PT_LOAD
  b.writeUInt32LE(dataOff, phoff + 4);
  b.writeUInt32LE(paddr + 0x100, phoff + 8); // vaddr differs: the loader uses paddr
  b.writeUInt32LE(paddr, phoff + 12);
  b.writeUInt32LE(data.length, phoff + 16);
  b.writeUInt32LE(data.length + 16, phoff + 20);
  data.copy(b, dataOff);
  symtab.copy(b, symOff);
  strtab.copy(b, strOff);
  const sh = (i, type, off, size, link) => {
    const at = shoff + 40 * i;
    b.writeUInt32LE(type, at + 4);
    b.writeUInt32LE(off, at + 16);
    b.writeUInt32LE(size, at + 20);
    b.writeUInt32LE(link, at + 24);
  };
  sh(1, 2, symOff, symtab.length, 2);
  sh(2, 3, strOff, strtab.length, 0);
  return new Uint8Array(b);
}

test('the ELF loader places segments at their load address and finds symbols', () => {
  const file = elf({ paddr: 0x10000000, data: Buffer.from('boot2'), symbol: '_SEGGER_RTT', value: 0x20000010 });
  const segments = loadableSegments(file, 'x.elf');
  assert.equal(segments.length, 1);
  assert.equal(segments[0].address, 0x10000000);
  assert.equal(Buffer.from(segments[0].bytes).toString(), 'boot2');
  assert.equal(findSymbol(file, 'x.elf', '_SEGGER_RTT'), 0x20000010);
  assert.equal(findSymbol(file, 'x.elf', '_SEGGER'), undefined);
  assert.throws(() => loadableSegments(Uint8Array.of(1, 2, 3), 'bad.bin'), /bad.bin: not an ELF file/);
});

test('the RTT reader takes what the firmware wrote, across the wrap, and frees it', () => {
  const sram = new Uint8Array(0x400);
  const mcu = { sram, sramView: new DataView(sram.buffer) };
  const base = 0x20000000;
  const block = 0x100;
  const buffer = 0x200;
  Buffer.from('SEGGER RTT').copy(Buffer.from(sram.buffer), block);
  const v = mcu.sramView;
  v.setUint32(block + 24 + 4, base + buffer, true);
  v.setUint32(block + 24 + 8, 8, true); // size
  const reader = new RttReader(mcu, base + block);
  assert.equal(reader.take().length, 0);
  sram.set([1, 2, 3, 4, 5, 6], buffer);
  v.setUint32(block + 24 + 12, 6, true); // write
  assert.deepEqual([...reader.take()], [1, 2, 3, 4, 5, 6]);
  sram.set([7, 8], buffer + 6);
  sram.set([9], buffer);
  v.setUint32(block + 24 + 12, 1, true); // wrapped
  assert.deepEqual([...reader.take()], [7, 8, 9]);
  assert.equal(v.getUint32(block + 24 + 16, true), 1, 'read offset advanced');
  assert.equal(new RttReader(mcu, undefined).take().length, 0);
});

test('sync messages carry the time and bytes; sync answers are parsed', () => {
  const t = timed(1500, [1, 2]);
  assert.equal(t.readDoubleLE(0), 1500);
  assert.deepEqual([...t.subarray(8)], [1, 2]);
  // The layout of src/rig/sim/pico/link.rs `encode_sync_reply` (its unit test).
  const reply = Buffer.from([1, 2, 0, 14, 1, 15, 0, 0, 1, 2]);
  assert.deepEqual(parseSyncReply(reply), {
    hostOpen: true,
    inputs: [
      { gpio: 14, level: true },
      { gpio: 15, level: false },
    ],
    hostBytes: Buffer.from([0, 1, 2]),
  });
});
