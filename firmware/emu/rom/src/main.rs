//! A boot ROM for the emulated RP2040 of `firmware/emu`, written for this project.
//!
//! The rp2040js emulator ships no boot ROM, and Raspberry Pi's (pico-bootrom) cannot be
//! vendored here: its floating-point library (`mufplib`) may be used "solely on a Raspberry
//! Pi RP2040 device" (its licence header), which an emulator on a PC is not. The bench
//! firmware needs little of it, so this ROM provides exactly that, at the places the
//! RP2040 datasheet fixes (chapter "Bootrom"):
//!
//! - the header: initial stack pointer and reset vector at 0x00/0x04, the magic `'M' 'u' 1`
//!   and the ROM version at 0x10–0x13, 16-bit pointers to the function table, the data
//!   table and the table lookup function at 0x14/0x16/0x18;
//! - the boot path of a flash boot: copy the second-stage bootloader (boot2, the
//!   first 256 bytes of flash) to SRAM at 0x20041F00, check its CRC-32 like the real ROM
//!   and enter it with `lr = 0` (boot2 then maps flash and jumps to the application's vector
//!   table at 0x10000100). An image without a valid boot2 stops at a breakpoint with
//!   [`BKPT_BAD_BOOT2`], where the real chip would fall back to USB boot mode;
//! - the functions the firmware looks up: `memcpy44` (`C4`) and the flash-access entry points
//!   embassy-rp calls around a flash command (`IF`, `EX`, `FC`, `CX`). The emulator models
//!   neither the QSPI pads, an XIP cache nor the flash chip's XIP state (its flash reads
//!   always return the image), so these four only return; the command itself goes through
//!   the emulated SSI, which the harness models for the commands the firmware sends.
//!
//! A code the table does not hold looks up as a null pointer, as in the real ROM; a fault
//! stops at a breakpoint with [`BKPT_FAULT`], which the harness reports.
#![no_std]
#![no_main]

use core::arch::{asm, global_asm};

/// Where the real ROM loads boot2 and puts the initial stack just below it.
const BOOT2_RAM: u32 = 0x2004_1f00;
/// Start of flash (XIP), where boot2 is stored.
const FLASH_BASE: u32 = 0x1000_0000;
/// Words of boot2, its CRC included (256 bytes).
const BOOT2_WORDS: usize = 64;

/// Breakpoint number when boot2's CRC does not match (no valid image in flash).
pub const BKPT_BAD_BOOT2: u8 = 0x01;
/// Breakpoint number of the fault handler (NMI and HardFault).
pub const BKPT_FAULT: u8 = 0x02;

// The header and tables hold 16-bit addresses, which the linker cannot relocate (no
// R_ARM_ABS16 in lld): every address in them is a difference from `rom_header` (linked at
// 0, so the difference is the address) of a label in this same section, which the assembler
// resolves itself. The labels are trampolines into the Rust functions (`+ 1`: Thumb).
global_asm!(
    ".section .rom_header, \"ax\"",
    ".balign 4",
    "rom_header:",
    ".word 0x20041f00",       // initial SP: BOOT2_RAM
    ".word rom_reset",        // reset
    ".word rom_fault",        // NMI
    ".word rom_fault",        // HardFault
    ".byte 0x4d, 0x75, 0x01", // magic 'M' 'u' 1
    ".byte 0x02",             // version: B1, the revision rp2040js was developed against
    ".hword rom_func_table - rom_header",
    ".hword rom_data_table - rom_header",
    ".hword t_lookup - rom_header + 1",
    ".balign 4",
    // Tables: pairs of (two-character code, 16-bit address), ended by a zero code.
    "rom_func_table:",
    ".hword 0x3443, t_memcpy44 - rom_header + 1", // 'C4'
    ".hword 0x4649, t_flash - rom_header + 1",    // 'IF' connect_internal_flash
    ".hword 0x5845, t_flash - rom_header + 1",    // 'EX' flash_exit_xip
    ".hword 0x4346, t_flash - rom_header + 1",    // 'FC' flash_flush_cache
    ".hword 0x5843, t_flash - rom_header + 1",    // 'CX' flash_enter_cmd_xip
    ".hword 0",
    "rom_data_table:",
    ".hword 0",
    ".balign 4",
    // Trampolines: r3 is free in every one of these calls (an argument register none of
    // them takes, caller-saved by the AAPCS).
    ".thumb",
    "t_lookup:",
    "ldr r3, =rom_table_lookup",
    "bx r3",
    "t_memcpy44:",
    "ldr r3, =rom_memcpy44",
    "bx r3",
    "t_flash:",
    "ldr r3, =rom_flash_return",
    "bx r3",
    ".ltorg",
);

/// `rom_table_lookup(table, code)`: the address stored for `code`, or null.
///
/// # Safety
/// `table` must point at a zero-terminated table of (code, address) half-word pairs.
#[no_mangle]
pub unsafe extern "C" fn rom_table_lookup(table: *const u16, code: u32) -> usize {
    let mut entry = table;
    loop {
        let c = u32::from(*entry);
        if c == 0 {
            return 0;
        }
        if c == code {
            return usize::from(*entry.add(1));
        }
        entry = entry.add(2);
    }
}

/// `memcpy44(dest, src, n)`: copy `n` bytes (a multiple of 4) between word-aligned
/// buffers; returns `dest`.
///
/// # Safety
/// Both buffers must be word aligned, valid for `n` bytes and must not overlap.
#[no_mangle]
pub unsafe extern "C" fn rom_memcpy44(dest: *mut u32, src: *const u32, n: u32) -> *mut u32 {
    for i in 0..(n / 4) as usize {
        dest.add(i).write_volatile(src.add(i).read_volatile());
    }
    dest
}

/// The flash-access entry points: nothing to do in the emulator (see the module doc).
#[no_mangle]
pub extern "C" fn rom_flash_return() {}

/// CRC-32/MPEG-2 (polynomial 0x04C11DB7, initial value all ones, no reflection, no final
/// XOR), the check the ROM applies to boot2's first 252 bytes before running it.
fn crc32_mpeg2(words: &[u32]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for w in words {
        for byte in w.to_le_bytes() {
            crc ^= u32::from(byte) << 24;
            for _ in 0..8 {
                crc = if crc & 0x8000_0000 != 0 {
                    (crc << 1) ^ 0x04c1_1db7
                } else {
                    crc << 1
                };
            }
        }
    }
    crc
}

/// Reset: load boot2 from flash into SRAM, check it and enter it.
///
/// # Safety
/// Runs once, as the reset vector, on the boot stack.
#[no_mangle]
pub unsafe extern "C" fn rom_reset() -> ! {
    let flash = FLASH_BASE as *const u32;
    let ram = BOOT2_RAM as *mut u32;
    let mut boot2 = [0u32; BOOT2_WORDS];
    for (i, w) in boot2.iter_mut().enumerate() {
        *w = flash.add(i).read_volatile();
        ram.add(i).write_volatile(*w);
    }
    if crc32_mpeg2(&boot2[..BOOT2_WORDS - 1]) != boot2[BOOT2_WORDS - 1] {
        loop {
            asm!("bkpt #{n}", n = const BKPT_BAD_BOOT2);
        }
    }
    // Enter boot2 (Thumb) with lr = 0: boot2 then vectors into the application instead
    // of returning (its exit routine tests lr).
    asm!(
        "movs r0, #0",
        "mov lr, r0",
        "bx r1",
        in("r1") BOOT2_RAM | 1,
        options(noreturn)
    );
}

/// NMI and HardFault: stop where the harness sees it.
#[no_mangle]
pub extern "C" fn rom_fault() -> ! {
    loop {
        unsafe { asm!("bkpt #{n}", n = const BKPT_FAULT) };
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    rom_fault()
}
