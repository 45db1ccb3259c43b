// Corrections to rp2040js 1.4.1 where it differs from the RP2040 silicon in ways the bench
// firmware depends on. Each one restores the behaviour the RP2040 datasheet describes; the
// write-ups in ../README.md are phrased so they can be filed upstream as they stand.
//
// Owns these patches only. It does not own the USB host (usb-host.mjs) or the link to the
// bench (link.mjs).

import { BasePeripheral } from 'rp2040js';

// DW_apb_i2c interrupt bit (RP2040 datasheet, I2C registers, IC_RAW_INTR_STAT).
const I2C_TX_EMPTY = 1 << 4;

/**
 * I²C: raise TX_EMPTY when a transfer is aborted.
 *
 * Silicon: an abort (for instance the target not acknowledging its address) flushes the TX
 * FIFO (IC_TX_ABRT_SOURCE.TX_FLUSH_CNT counts the flushed commands), and TX_EMPTY is set
 * whenever the FIFO is at or below IC_TX_TL, so it is set after the flush (RP2040
 * datasheet, I2C registers, IC_RAW_INTR_STAT.TX_EMPTY). rp2040js flushes the FIFO but
 * leaves TX_EMPTY clear, and embassy-rp's blocking write, which waits for TX_EMPTY before
 * reading the abort reason, then spins for ever on a missing sensor.
 * @param {import('rp2040js').RPI2C} i2c
 */
export function raiseTxEmptyOnAbort(i2c) {
  const abort = i2c.abort;
  i2c.abort = function (reason) {
    abort.call(this, reason);
    if (this.txFIFO.itemCount <= this.txThreshold) {
      this.setInterrupts(I2C_TX_EMPTY);
    }
  };
}

// USB DPRAM layout and buffer control bits (RP2040 datasheet, USB, DPSRAM).
const EP1_IN_BUFFER_CONTROL = 0x88;
const EP15_OUT_BUFFER_CONTROL = 0xfc;
const EP1_IN_CONTROL = 0x08;
const BUF_FULL = 1 << 15;
const BUF_AVAILABLE = 1 << 10;
const BUF_LEN_MASK = 0x3ff;
const EP_CTRL_DOUBLE_BUF = 1 << 30;

/**
 * USB device mode, data endpoints: a buffer handed to the controller stays "available"
 * (owned by the controller) until the host has transferred a packet into or out of it.
 *
 * Silicon: the controller clears AVAILABLE in the buffer control word only when a
 * transaction completes, setting FULL and the length for an OUT packet received, clearing
 * FULL for an IN packet sent (RP2040 datasheet, USB, buffer control); until then the host
 * is NAKed. rp2040js
 * clears AVAILABLE as soon as the firmware sets it. For OUT endpoints that makes the
 * firmware take the buffer at once, with the length it armed (64) and its old contents:
 * embassy-rp's `read` then returns a stale packet, and one Hello from the host was answered
 * more than 40 times. For IN endpoints it makes every packet "sent" even when no host
 * reads, so a board whose host closed the port never sees its writes time out.
 *
 * After this patch an armed OUT buffer waits for `completeOut` (the host sending a packet)
 * and an armed IN buffer waits for `completeIn` (the host reading one). Endpoint 0 and
 * double-buffered endpoints (embassy-rp uses neither for CDC data) keep rp2040js's handling.
 *
 * @param {import('rp2040js').RPUSBController} usb
 * @param {{ onOutArmed: (endpoint: number, length: number) => void,
 *           onInArmed: (endpoint: number, packet: Uint8Array) => void }} host
 * @returns {{ completeOut: (endpoint: number, data: Uint8Array) => void,
 *             completeIn: (endpoint: number) => void }}
 */
export function holdDataEndpointBuffers(usb, host) {
  const dpram = usb.rp2040.usbDPRAMView;
  const original = usb.DPRAMUpdated.bind(usb);
  const doubleBuffered = (endpoint, out) =>
    !!(dpram.getUint32(EP1_IN_CONTROL + 8 * (endpoint - 1) + (out ? 4 : 0), true) & EP_CTRL_DOUBLE_BUF);
  usb.DPRAMUpdated = (offset, value) => {
    const dataEndpoint = offset >= EP1_IN_BUFFER_CONTROL && offset <= EP15_OUT_BUFFER_CONTROL;
    if (usb.hostMode || !dataEndpoint || !(value & BUF_AVAILABLE)) {
      original(offset, value);
      return;
    }
    const endpoint = (offset - 0x80) >> 3;
    const out = (offset & 4) !== 0;
    if (doubleBuffered(endpoint, out)) {
      original(offset, value);
      return;
    }
    if (out) {
      host.onOutArmed(endpoint, value & BUF_LEN_MASK);
    } else {
      const start = usb.getEndpointBufferOffset(endpoint, false);
      host.onInArmed(endpoint, usb.rp2040.usbDPRAM.slice(start, start + (value & BUF_LEN_MASK)));
    }
  };
  return {
    completeOut(endpoint, data) {
      const reg = 0x84 + endpoint * 8;
      let control = dpram.getUint32(reg, true);
      const length = Math.min(data.length, control & BUF_LEN_MASK);
      usb.rp2040.usbDPRAM.set(data.subarray(0, length), usb.getEndpointBufferOffset(endpoint, true));
      control = (control & ~(BUF_AVAILABLE | BUF_LEN_MASK)) | BUF_FULL | length;
      dpram.setUint32(reg, control, true);
      usb.indicateBufferReady(endpoint, true);
    },
    completeIn(endpoint) {
      const reg = 0x80 + endpoint * 8;
      dpram.setUint32(reg, dpram.getUint32(reg, true) & ~(BUF_AVAILABLE | BUF_FULL), true);
      usb.indicateBufferReady(endpoint, false);
    },
  };
}

// SSI registers (RP2040 datasheet, SSI registers).
const SSI_CTRLR0 = 0x00;
const SSI_CTRLR1 = 0x04;
const SSI_SSIENR = 0x08;
const SSI_DR0 = 0x60;
const TMOD_EEPROM_READ = 3;
/** W25Q16JV "Read Unique ID Number" (Winbond datasheet): 4 dummy bytes, then 8 ID bytes. */
const FLASH_READ_UNIQUE_ID = 0x4b;

/**
 * SSI: answer the flash's "Read Unique ID" command with the board's 64-bit ID.
 *
 * Silicon: with the SSI in EEPROM-read mode (CTRLR0.TMOD = 3), the command byte written to
 * DR0 goes out on the QSPI bus and CTRLR1.NDF + 1 frames of the flash's answer come back in
 * the RX FIFO (RP2040 datasheet, SSI); for 0x4B a W25Q16JV answers 4 dummy bytes and its
 * factory-programmed 64-bit unique ID. rp2040js has no flash chip behind its SSI (DR0 reads
 * 0 apart from a status-register stub for boot2), so every emulated board reads the ID
 * 00…00, and the board's USB serial number, which is that ID in hex, cannot tell two
 * boards apart. Other commands keep rp2040js's behaviour.
 * @param {BasePeripheral} ssi the SSI peripheral (rp2040.peripherals[0x18000])
 * @param {Uint8Array} uniqueId the 8-byte ID
 */
export function answerFlashUniqueId(ssi, uniqueId) {
  const read = ssi.readUint32.bind(ssi);
  const write = ssi.writeUint32.bind(ssi);
  let ctrlr0 = 0;
  let ctrlr1 = 0;
  let expectCommand = false;
  const rx = [];
  ssi.writeUint32 = (offset, value) => {
    if (offset === SSI_CTRLR0) {
      ctrlr0 = value;
    } else if (offset === SSI_CTRLR1) {
      ctrlr1 = value;
    } else if (offset === SSI_SSIENR) {
      expectCommand = (value & 1) === 1;
      rx.length = 0;
    } else if (offset === SSI_DR0 && expectCommand) {
      expectCommand = false;
      const eepromRead = ((ctrlr0 >> 8) & 3) === TMOD_EEPROM_READ;
      if (eepromRead && (value & 0xff) === FLASH_READ_UNIQUE_ID) {
        const answer = [0, 0, 0, 0, ...uniqueId];
        const frames = (ctrlr1 & 0xffff) + 1;
        for (let i = 0; i < frames; i++) {
          rx.push(i < answer.length ? answer[i] : 0xff);
        }
        return;
      }
    }
    write(offset, value);
  };
  ssi.readUint32 = (offset) => (offset === SSI_DR0 && rx.length > 0 ? rx.shift() : read(offset));
}

// XIP_CTRL registers (RP2040 datasheet, XIP).
const XIP_STAT = 0x08;
const XIP_STAT_FIFO_EMPTY = 1 << 1;
const XIP_STAT_FLUSH_READY = 1 << 0;

/** The XIP cache controller at 0x14000000, as far as the firmware reads it. */
class XipControl extends BasePeripheral {
  constructor(rp2040) {
    super(rp2040, 'XIP_CTRL');
    this.ctrl = 0x3;
  }

  readUint32(offset) {
    switch (offset) {
      case 0x00:
        return this.ctrl;
      case XIP_STAT:
        return XIP_STAT_FIFO_EMPTY | XIP_STAT_FLUSH_READY;
      default:
        // FLUSH, the hit/access counters, STREAM_ADDR and STREAM_CTR: no streaming, no cache.
        return 0;
    }
  }

  writeUint32(offset, value) {
    if (offset === 0x00) {
      this.ctrl = value;
    }
  }
}

/**
 * XIP_CTRL: map the block at 0x14000000.
 *
 * Silicon: XIP_CTRL holds the cache control, flush and streaming registers; STREAM_CTR
 * reads 0 when no streaming transfer is in progress (RP2040 datasheet, XIP). rp2040js maps
 * nothing there and answers 0xFFFFFFFF, so embassy-rp's flash access, which waits for
 * STREAM_CTR to reach 0 before running from RAM, never starts. The emulated block has no
 * cache and never streams: STREAM_CTR and the counters read 0.
 * @param {import('rp2040js').RP2040} mcu
 */
export function mapXipControl(mcu) {
  mcu.peripherals[(0x14000000 >>> 14) << 2] = new XipControl(mcu);
}
