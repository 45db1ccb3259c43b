// Loading a 32-bit little-endian ARM ELF executable into the emulated address space.
//
// Owns reading the program headers and copying each loadable segment's file bytes to its
// physical address (`p_paddr`, the load address: for the board image, flash at 0x10000000
// also holds the initial values of `.data`, which the firmware copies to RAM itself). It
// does not own where the bytes go: the caller passes a `write(address, bytes)`. Symbols are
// read only for the RTT control block (`findSymbol`).

const PT_LOAD = 1;
const SHT_SYMTAB = 2;

/** An ELF file that cannot be loaded: says what is wrong with it. */
export class ElfError extends Error {
  constructor(path, message) {
    super(`${path}: ${message}`);
    this.name = 'ElfError';
  }
}

function header(bytes, path) {
  if (bytes.length < 52 || bytes[0] !== 0x7f || bytes[1] !== 0x45 || bytes[2] !== 0x4c || bytes[3] !== 0x46) {
    throw new ElfError(path, 'not an ELF file');
  }
  if (bytes[4] !== 1 || bytes[5] !== 1) {
    throw new ElfError(path, 'not a 32-bit little-endian ELF file (the RP2040 image is one)');
  }
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const machine = view.getUint16(18, true);
  if (machine !== 40) {
    throw new ElfError(path, `machine ${machine} is not ARM (40)`);
  }
  return view;
}

/**
 * The loadable segments of an ELF image: `{ address, bytes }` with the physical address
 * and the bytes stored in the file (`p_filesz`; the zero-filled rest is the program's job).
 * @param {Uint8Array} bytes the file
 * @param {string} path for error messages
 * @returns {{address: number, bytes: Uint8Array}[]}
 */
export function loadableSegments(bytes, path) {
  const view = header(bytes, path);
  const phoff = view.getUint32(28, true);
  const phentsize = view.getUint16(42, true);
  const phnum = view.getUint16(44, true);
  const segments = [];
  for (let i = 0; i < phnum; i++) {
    const at = phoff + i * phentsize;
    if (at + 32 > bytes.length) {
      throw new ElfError(path, `program header ${i} lies past the end of the file`);
    }
    if (view.getUint32(at, true) !== PT_LOAD) {
      continue;
    }
    const offset = view.getUint32(at + 4, true);
    const paddr = view.getUint32(at + 12, true);
    const filesz = view.getUint32(at + 16, true);
    if (filesz === 0) {
      continue;
    }
    if (offset + filesz > bytes.length) {
      throw new ElfError(path, `segment ${i} (${filesz} bytes at file offset ${offset}) is cut off`);
    }
    segments.push({ address: paddr >>> 0, bytes: bytes.subarray(offset, offset + filesz) });
  }
  if (segments.length === 0) {
    throw new ElfError(path, 'no loadable segment');
  }
  return segments;
}

/**
 * The value of a symbol from the ELF symbol table, or `undefined` when the file has no
 * symbol table or no such symbol.
 * @param {Uint8Array} bytes the file
 * @param {string} path for error messages
 * @param {string} name the symbol
 * @returns {number | undefined}
 */
export function findSymbol(bytes, path, name) {
  const view = header(bytes, path);
  const shoff = view.getUint32(32, true);
  const shentsize = view.getUint16(46, true);
  const shnum = view.getUint16(48, true);
  const want = new TextEncoder().encode(name);
  for (let i = 0; i < shnum; i++) {
    const sh = shoff + i * shentsize;
    if (sh + 40 > bytes.length || view.getUint32(sh + 4, true) !== SHT_SYMTAB) {
      continue;
    }
    const symOff = view.getUint32(sh + 16, true);
    const symSize = view.getUint32(sh + 20, true);
    const strSection = shoff + view.getUint32(sh + 24, true) * shentsize;
    const strOff = view.getUint32(strSection + 16, true);
    for (let s = symOff; s + 16 <= symOff + symSize; s += 16) {
      const nameAt = strOff + view.getUint32(s, true);
      let match = nameAt + want.length < bytes.length && bytes[nameAt + want.length] === 0;
      for (let k = 0; match && k < want.length; k++) {
        match = bytes[nameAt + k] === want[k];
      }
      if (match) {
        return view.getUint32(s + 4, true);
      }
    }
  }
  return undefined;
}
