// Each correction in lib/fixes.mjs against the plain emulator: the deviation is there
// without it and gone with it.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { RP2040 } from 'rp2040js';

import {
  answerFlashUniqueId,
  holdDataEndpointBuffers,
  mapXipControl,
  raiseTxEmptyOnAbort,
} from '../lib/fixes.mjs';

const I2C0 = 0x40044000;
const IC_ENABLE = 0x6c;
const IC_DATA_CMD = 0x10;
const IC_RAW_INTR_STAT = 0x34;
const TX_EMPTY = 1 << 4;
const TX_ABRT = 1 << 6;

function quietChip() {
  const mcu = new RP2040();
  mcu.logger = { debug() {}, info() {}, warn() {}, error() {} };
  return mcu;
}

/** A write to an address nobody acknowledges; returns IC_RAW_INTR_STAT afterwards. */
function writeToAbsentTarget(fixed) {
  const mcu = quietChip();
  if (fixed) {
    raiseTxEmptyOnAbort(mcu.i2c[0]);
  }
  mcu.i2c[0].onConnect = () => mcu.i2c[0].completeConnect(false);
  mcu.writeUint32(I2C0 + IC_ENABLE, 1);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x0b | (1 << 9)); // one byte with STOP
  return mcu.readUint32(I2C0 + IC_RAW_INTR_STAT);
}

test('an I2C address NACK aborts and raises TX_EMPTY, as on silicon', () => {
  const plain = writeToAbsentTarget(false);
  assert.equal(plain & TX_ABRT, TX_ABRT);
  assert.equal(plain & TX_EMPTY, 0, 'rp2040js 1.4.1 leaves TX_EMPTY clear (the deviation)');
  const fixed = writeToAbsentTarget(true);
  assert.equal(fixed & (TX_ABRT | TX_EMPTY), TX_ABRT | TX_EMPTY);
});

const USB_DPRAM = 0x50100000;
const EP1_OUT_CONTROL = 0x0c;
const EP1_OUT_BUFFER_CONTROL = 0x8c;
const AVAILABLE = 1 << 10;
const FULL = 1 << 15;

function armOut(mcu) {
  mcu.writeUint32(USB_DPRAM + EP1_OUT_CONTROL, (1 << 31) | 0x180); // enabled, buffer at 0x180
  mcu.writeUint32(USB_DPRAM + EP1_OUT_BUFFER_CONTROL, AVAILABLE | 64);
  return () => mcu.readUint32(USB_DPRAM + EP1_OUT_BUFFER_CONTROL);
}

test('an armed OUT buffer stays available until the host sends a packet', () => {
  const plain = quietChip();
  plain.usbCtrl.onEndpointRead = () => {};
  assert.equal(armOut(plain)() & AVAILABLE, 0, 'rp2040js hands the buffer back at once (the deviation)');

  const mcu = quietChip();
  const armed = [];
  const buffers = holdDataEndpointBuffers(mcu.usbCtrl, {
    onOutArmed: (endpoint, length) => armed.push([endpoint, length]),
    onInArmed: () => {},
  });
  const control = armOut(mcu);
  assert.deepEqual(armed, [[1, 64]]);
  assert.equal(control() & AVAILABLE, AVAILABLE, 'still owned by the controller');
  buffers.completeOut(1, Uint8Array.of(1, 2, 3));
  assert.equal(control() & (AVAILABLE | FULL | 0x3ff), FULL | 3);
  assert.deepEqual([...mcu.usbDPRAM.subarray(0x180, 0x183)], [1, 2, 3]);
  assert.equal(mcu.usbCtrl.buffStatus & (1 << 3), 1 << 3, 'BUFF_STATUS bit of EP1 OUT');
});

const SSI = 0x18000000;

test('the flash answers Read Unique ID with the board ID', () => {
  const id = Uint8Array.of(0xe6, 0x60, 0x58, 0x38, 0x83, 0x3c, 0x2b, 0x2f);
  const read = (fixed) => {
    const mcu = quietChip();
    if (fixed) {
      answerFlashUniqueId(mcu.peripherals[0x18000], id);
    }
    mcu.writeUint32(SSI + 0x08, 0); // SSIENR off
    mcu.writeUint32(SSI + 0x00, 3 << 8); // TMOD = EEPROM read
    mcu.writeUint32(SSI + 0x04, 4 + 8 - 1); // 4 dummy + 8 data frames
    mcu.writeUint32(SSI + 0x08, 1);
    mcu.writeUint32(SSI + 0x60, 0x4b);
    const out = [];
    for (let i = 0; i < 12; i++) {
      out.push(mcu.readUint32(SSI + 0x60) & 0xff);
    }
    return out.slice(4);
  };
  assert.deepEqual(read(false), [0, 0, 0, 0, 0, 0, 0, 0], 'rp2040js has no flash chip (the deviation)');
  assert.deepEqual(read(true), [...id]);
});

test('XIP_CTRL is mapped and STREAM_CTR reads 0', () => {
  const plain = quietChip();
  assert.equal(plain.readUint32(0x14000018), 0xffffffff, 'unmapped in rp2040js (the deviation)');
  const mcu = quietChip();
  mapXipControl(mcu);
  assert.equal(mcu.readUint32(0x14000018), 0);
  assert.equal(mcu.readUint32(0x14000008) & 0b11, 0b11, 'FIFO empty, flush ready');
});
