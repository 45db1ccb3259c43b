#!/usr/bin/env node
// The emulated board: the bench firmware's release image on rp2040js, wired to the bench.
//
//   node harness.mjs --rom ROM.elf --image FIRMWARE.elf [--flash-id 16HEX] [--slice-us 1000]
//
// It is started by `mpc-rig sim-device pico` (src/rig/sim/pico), which owns everything
// outside the chip: the pseudo-terminal the host opens, the stepper driver on the STEP/DIR/EN
// pins, the AS5600/BNO055 register models on the I²C buses, the quadrature and e-stop inputs,
// the plant, and the pacing to the wall clock. This process owns the chip: it loads the boot
// ROM (rom/, our own) and the image, applies the corrections in lib/fixes.mjs, plays the USB
// host (lib/usb-host.mjs), and runs the CPU in slices of simulated time. Between slices and
// whenever the firmware touches a pin or an I²C bus it talks to the bench over the pipe in
// lib/link.mjs. It knows nothing of the bench's wiring: it reports every GPIO and every I²C
// transfer with the pins its controller is routed to, and the bench decides what is
// connected where.
//
// Standard output carries the pipe; human-readable messages go to standard error.

import * as fs from 'node:fs';
import { parseArgs } from 'node:util';
import { GPIOPinState, RP2040 } from 'rp2040js';

import { findSymbol, loadableSegments } from './lib/elf.mjs';
import { answerFlashUniqueId, mapXipControl, raiseTxEmptyOnAbort } from './lib/fixes.mjs';
import { I2cKind, Link, LogLevel, Reply, Tag, parseSyncReply, timed } from './lib/link.mjs';
import { RttReader } from './lib/rtt.mjs';
import { UsbHost } from './lib/usb-host.mjs';

const FLASH_BASE = 0x10000000;
/** The ROM's size (RP2040 datasheet, address map). */
const ROM_SIZE = 16 * 1024;
/** I²C function of a GPIO (RP2040 datasheet, GPIO function table: F3). */
const FUNCSEL_I2C = 3;
const NO_PIN = 0xff;
/** Exception number of HardFault (IPSR). */
const HARD_FAULT = 3;

// rp2040js logs through `console`; standard output is the pipe.
console.log = console.info = console.debug = console.error;

function usage(message) {
  process.stderr.write(`harness: ${message}\n`);
  process.exit(2);
}

const { values: args } = parseArgs({
  options: {
    rom: { type: 'string' },
    image: { type: 'string' },
    'flash-id': { type: 'string', default: 'e6605838833c2b2f' },
    'slice-us': { type: 'string', default: '1000' },
  },
});
if (!args.rom || !args.image) {
  usage('give --rom ROM.elf and --image FIRMWARE.elf');
}
if (!/^[0-9a-fA-F]{16}$/.test(args['flash-id'])) {
  usage(`--flash-id ${args['flash-id']}: expected 16 hex digits (the flash's 64-bit unique ID)`);
}
const sliceNs = Number(args['slice-us']) * 1000;
if (!(sliceNs > 0)) {
  usage(`--slice-us ${args['slice-us']}: expected a positive number`);
}

function readElf(path) {
  try {
    const bytes = new Uint8Array(fs.readFileSync(path));
    return { bytes, segments: loadableSegments(bytes, path) };
  } catch (e) {
    usage(e.message);
  }
}

const mcu = new RP2040();
const { clock } = mcu;
const link = new Link();

/** A line for the bench's log at `level` (LogLevel in link.mjs). */
function log(line, level = LogLevel.WARN) {
  link.post(Tag.LOG, Buffer.concat([Buffer.of(level), Buffer.from(line, 'utf8')]));
}
// The emulator's own messages (unmodelled registers the firmware touches at boot, SEV) are
// debug detail; its errors are not.
mcu.logger = {
  debug() {},
  info() {},
  warn: (component, message) => log(`rp2040js ${component}: ${message}`, LogLevel.DEBUG),
  error: (component, message) => log(`rp2040js ${component}: ${message}`, LogLevel.WARN),
};

// The boot ROM, then the image (loadBootrom resets the chip, erasing the flash).
const rom = new Uint8Array(ROM_SIZE);
for (const s of readElf(args.rom).segments) {
  if (s.address + s.bytes.length > ROM_SIZE) {
    usage(`${args.rom}: a segment at 0x${s.address.toString(16)} lies outside the 16 KiB ROM`);
  }
  rom.set(s.bytes, s.address);
}
mcu.loadBootrom(new Uint32Array(rom.buffer));
const image = readElf(args.image);
for (const s of image.segments) {
  if (s.address < FLASH_BASE || s.address + s.bytes.length > FLASH_BASE + mcu.flash.length) {
    usage(`${args.image}: a segment at 0x${s.address.toString(16)} lies outside flash`);
  }
  mcu.flash.set(s.bytes, s.address - FLASH_BASE);
}

for (const i2c of mcu.i2c) {
  raiseTxEmptyOnAbort(i2c);
}
mapXipControl(mcu);
answerFlashUniqueId(mcu.peripherals[0x18000], Buffer.from(args['flash-id'], 'hex'));

const now = () => clock.nanos / 1000;

// GPIO: every change of every pin goes to the bench.
function levelOf(state) {
  if (state === GPIOPinState.High) {
    return 1;
  }
  return state === GPIOPinState.Low ? 0 : 2;
}
mcu.gpio.forEach((pin, index) => {
  pin.addListener((state) => link.post(Tag.PIN, timed(now(), [index, levelOf(state)])));
});

// I²C: transfers go to the bench with the pins the controller is routed to.
function routedPins(controller) {
  let sda = NO_PIN;
  let scl = NO_PIN;
  for (let n = mcu.gpio.length - 1; n >= 0; n--) {
    if (mcu.gpio[n].functionSelect === FUNCSEL_I2C && ((n >> 1) & 1) === controller) {
      if (n & 1) {
        scl = n;
      } else {
        sda = n;
      }
    }
  }
  return [sda, scl];
}
function i2cPayload(controller, kind, arg) {
  return timed(now(), [controller, ...routedPins(controller), kind, arg]);
}
function i2cRequest(controller, kind, arg) {
  const reply = link.request(Tag.I2C, i2cPayload(controller, kind, arg));
  if (reply === null) {
    finish();
  }
  if (reply.tag !== Reply.I2C) {
    throw new Error(`bench answered an I2C event with tag 0x${reply.tag.toString(16)}`);
  }
  return reply.payload.readUInt8(0);
}
mcu.i2c.forEach((i2c, controller) => {
  i2c.onStart = () => i2c.completeStart();
  i2c.onConnect = (address, mode) => {
    i2c.completeConnect(i2cRequest(controller, I2cKind.CONNECT, (address << 1) | mode) === 1);
  };
  i2c.onWriteByte = (value) => {
    // The bench's targets acknowledge every data byte (the sensors modelled do).
    link.post(Tag.I2C, i2cPayload(controller, I2cKind.WRITE, value));
    i2c.completeWrite(true);
  };
  i2c.onReadByte = (ack) => {
    i2c.completeRead(i2cRequest(controller, I2cKind.READ, ack ? 1 : 0));
  };
  i2c.onStop = () => {
    link.post(Tag.I2C, i2cPayload(controller, I2cKind.STOP, 0));
    i2c.completeStop();
  };
});

// USB.
let fromDevice = [];
const host = new UsbHost(mcu.usbCtrl, {
  onData: (bytes) => fromDevice.push(Buffer.from(bytes)),
  onEnumerated: (info) => link.post(Tag.USB, Buffer.from(JSON.stringify(info), 'utf8')),
  log,
});

// Breakpoints (the ROM's, or `bkpt` in the firmware) and hard faults stop the board.
let halted = null;
mcu.onBreak = (code) => {
  halted = `breakpoint 0x${code.toString(16)} at PC 0x${(mcu.core.PC >>> 0).toString(16)}`;
};

function finish() {
  link.flush();
  process.exit(0);
}

function halt(reason) {
  link.post(Tag.HALT, Buffer.from(reason, 'utf8'));
  finish();
}

// RTT: the firmware's defmt frames, read from its up-channel 0 as a debug probe would.
const rtt = new RttReader(mcu, findSymbol(image.bytes, args.image, '_SEGGER_RTT'));

/** Input changes for the next slice, spread evenly across it (all at once when `atOnce`). */
function applyInputs(inputs, atOnce) {
  inputs.forEach(({ gpio, level }, k) => {
    const pin = mcu.gpio[gpio];
    if (pin === undefined) {
      return;
    }
    if (atOnce) {
      pin.setInputValue(level);
    } else {
      clock.createAlarm(() => pin.setInputValue(level)).schedule(((k + 1) * sliceNs) / (inputs.length + 1));
    }
  });
}

function sync(initial = false) {
  const log = rtt.take();
  if (log.length > 0) {
    link.post(Tag.RTT, log);
  }
  const bytes = Buffer.concat(fromDevice);
  fromDevice = [];
  const reply = link.request(Tag.SYNC, timed(now(), bytes));
  if (reply === null) {
    finish();
  }
  if (reply.tag !== Reply.SYNC) {
    throw new Error(`bench answered SYNC with tag 0x${reply.tag.toString(16)}`);
  }
  const { hostOpen, inputs, hostBytes } = parseSyncReply(reply.payload);
  applyInputs(inputs, initial);
  if (hostOpen !== host.portOpen) {
    host.setPortOpen(hostOpen);
  }
  if (hostBytes.length > 0) {
    host.send(hostBytes);
  }
}

const { core } = mcu;
sync(true); // the initial input levels, before the first instruction
for (;;) {
  const end = clock.nanos + sliceNs;
  // clk_sys as the firmware configured it (125 MHz under embassy-rp's defaults).
  const cycleNs = 1e9 / mcu.clkSys;
  while (clock.nanos < end && halted === null) {
    if (core.waiting) {
      const next = clock.nanosToNextAlarm;
      clock.tick(next > 0 && clock.nanos + next < end ? next : end - clock.nanos);
    } else {
      clock.tick(core.executeInstruction() * cycleNs);
    }
  }
  if (halted !== null) {
    halt(halted);
  }
  if (core.IPSR === HARD_FAULT) {
    halt(`HardFault at PC 0x${(core.PC >>> 0).toString(16)}`);
  }
  sync();
}
