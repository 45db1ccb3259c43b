//! Put `rom.x` where the linker finds it, and rebuild when it changes.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("rom.x"), include_bytes!("rom.x")).expect("write rom.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=rom.x");
    println!("cargo:rerun-if-changed=build.rs");
}
