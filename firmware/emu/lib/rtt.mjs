// Reading the firmware's RTT up-channel 0 (SEGGER's Real-Time Transfer, which defmt-rtt
// writes its log frames to) out of emulated RAM, as a debug probe does on a real board.
//
// The control block `_SEGGER_RTT`: a 16-byte id ("SEGGER RTT"), the numbers of up and down
// channels (u32 each), then the up channels, 24 bytes each: name pointer, buffer pointer,
// size, write offset, read offset, flags. The reader copies what lies between the read and
// the write offsets and advances the read offset, which frees the space for the firmware.
// Owns that reading only; decoding the frames needs the image's symbols (`defmt-print`).

const RAM_BASE = 0x20000000;
const ID = 'SEGGER RTT';
const UP0 = 24;

export class RttReader {
  /**
   * @param {import('rp2040js').RP2040} mcu
   * @param {number | undefined} address of `_SEGGER_RTT` (undefined: the image has no RTT)
   */
  constructor(mcu, address) {
    this.ram = mcu.sram;
    this.view = mcu.sramView;
    this.at = address === undefined ? -1 : address - RAM_BASE;
  }

  /** The bytes written since the last call (empty before the firmware set the block up). */
  take() {
    const { at, ram, view } = this;
    if (at < 0 || at + UP0 + 24 > ram.length || Buffer.from(ram.subarray(at, at + ID.length)).toString('latin1') !== ID) {
      return Buffer.alloc(0);
    }
    const buffer = view.getUint32(at + UP0 + 4, true) - RAM_BASE;
    const size = view.getUint32(at + UP0 + 8, true);
    const write = view.getUint32(at + UP0 + 12, true);
    let read = view.getUint32(at + UP0 + 16, true);
    if (size === 0 || buffer < 0 || buffer + size > ram.length || write >= size || read >= size) {
      return Buffer.alloc(0);
    }
    const chunks = [];
    if (write < read) {
      chunks.push(ram.subarray(buffer + read, buffer + size));
      read = 0;
    }
    chunks.push(ram.subarray(buffer + read, buffer + write));
    view.setUint32(at + UP0 + 16, write, true);
    return Buffer.concat(chunks);
  }
}
