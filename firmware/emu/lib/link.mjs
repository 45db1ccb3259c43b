// The pipe between the emulated board (this process) and the bench that owns the plant, the
// sensors and the host's serial port (`mpc-rig sim-device pico`, src/rig/sim/pico/link.rs,
// which documents the protocol and is its other half).
//
// Every message is `tag:u8 · length:u32 LE · payload`. The board sends on standard output and
// reads the answers on standard input, blocking: the emulated CPU does not run while the
// bench computes an answer, so simulated time is the same on both sides. Messages that need
// no answer are buffered and flushed before the next one that does.

import * as fs from 'node:fs';

/** Board → bench. */
export const Tag = Object.freeze({
  /** End of a time slice: f64 simulated µs, then the bytes the board sent on USB. Answered. */
  SYNC: 0x01,
  /** A GPIO's level changed: f64 µs, u8 gpio, u8 level (0 low, 1 high, 2 not driven). */
  PIN: 0x02,
  /** An I²C bus event: f64 µs, u8 controller, u8 SDA gpio, u8 SCL gpio, u8 kind, u8 arg. */
  I2C: 0x03,
  /** USB enumeration finished: UTF-8 JSON {vid, pid, manufacturer, product, serial}. */
  USB: 0x04,
  /** A line for the bench's log: u8 level (LogLevel), then UTF-8 text. */
  LOG: 0x05,
  /** The emulated CPU stopped (UTF-8 reason); the board exits after it. */
  HALT: 0x06,
  /** Bytes the firmware wrote to its RTT up-channel 0 (defmt log frames). */
  RTT: 0x07,
});

/** Bench → board. */
export const Reply = Object.freeze({
  /** u8 flags (bit 0: the host holds the serial port open), u16 n, n × (u8 gpio, u8 level),
   *  then the bytes the host sent. */
  SYNC: 0x81,
  /** u8 value: the acknowledge bit of a CONNECT (1 = ACK), or the byte of a READ. */
  I2C: 0x82,
});

/** Levels of a LOG message. */
export const LogLevel = Object.freeze({ DEBUG: 0, WARN: 1 });

/** I²C event kinds (the `kind` byte of an I2C message). */
export const I2cKind = Object.freeze({
  /** The controller addresses a target: arg = address << 1 | read. Answered. */
  CONNECT: 0,
  /** A data byte written to the addressed target: arg = the byte. */
  WRITE: 1,
  /** A data byte read from the target: arg = 1 when the controller acknowledges it. Answered. */
  READ: 2,
  /** STOP condition. */
  STOP: 3,
});

/** The board's end of the pipe. */
export class Link {
  /**
   * @param {number} input file descriptor of the answers (standard input)
   * @param {number} output file descriptor of the messages (standard output)
   */
  constructor(input = 0, output = 1) {
    this.input = input;
    this.output = output;
    this.pending = [];
    this.pendingBytes = 0;
  }

  /** Queue a message that needs no answer. */
  post(tag, payload) {
    const head = Buffer.alloc(5);
    head.writeUInt8(tag, 0);
    head.writeUInt32LE(payload.length, 1);
    this.pending.push(head, payload);
    this.pendingBytes += 5 + payload.length;
  }

  /** Write everything queued. */
  flush() {
    if (this.pendingBytes === 0) {
      return;
    }
    const all = Buffer.concat(this.pending, this.pendingBytes);
    this.pending = [];
    this.pendingBytes = 0;
    let done = 0;
    while (done < all.length) {
      done += fs.writeSync(this.output, all, done, all.length - done);
    }
  }

  /**
   * Send a message (after everything queued) and wait for its answer.
   * @returns {{tag: number, payload: Buffer} | null} null when the bench closed the pipe
   */
  request(tag, payload) {
    this.post(tag, payload);
    this.flush();
    const head = this.readExactly(5);
    if (head === null) {
      return null;
    }
    const payloadIn = this.readExactly(head.readUInt32LE(1));
    return payloadIn === null ? null : { tag: head.readUInt8(0), payload: payloadIn };
  }

  readExactly(n) {
    const buf = Buffer.alloc(n);
    let got = 0;
    while (got < n) {
      let k;
      try {
        k = fs.readSync(this.input, buf, got, n - got, null);
      } catch (e) {
        if (e.code === 'EAGAIN') {
          continue;
        }
        if (e.code === 'EOF' || e.code === 'EPIPE') {
          return null;
        }
        throw e;
      }
      if (k === 0) {
        return null;
      }
      got += k;
    }
    return buf;
  }
}

/** f64 simulated time in µs followed by the given bytes. */
export function timed(timeUs, bytes) {
  const b = Buffer.alloc(8 + bytes.length);
  b.writeDoubleLE(timeUs, 0);
  b.set(bytes, 8);
  return b;
}

/**
 * Parse a SYNC answer.
 * @param {Buffer} payload
 * @returns {{hostOpen: boolean, inputs: {gpio: number, level: boolean}[], hostBytes: Buffer}}
 */
export function parseSyncReply(payload) {
  const flags = payload.readUInt8(0);
  const n = payload.readUInt16LE(1);
  const inputs = [];
  for (let i = 0; i < n; i++) {
    inputs.push({ gpio: payload.readUInt8(3 + 2 * i), level: payload.readUInt8(4 + 2 * i) !== 0 });
  }
  return { hostOpen: (flags & 1) !== 0, inputs, hostBytes: payload.subarray(3 + 2 * n) };
}
