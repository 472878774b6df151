//! Build script: one thing only. It hashes the engine's sources (`src/`, `shaders/`) into
//! `SCENESAMPLE_SOURCE_HASH`, so that what depends on the engine's speed (the `auto` backend's
//! calibration file, `calibration::cache`) is measured again after any change to it,
//! not only after a change of the package's version.

use std::path::{Path, PathBuf};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// 64-bit FNV-1a: enough to tell two source trees apart; nothing here needs a cryptographic hash.
fn fnv(hash: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *hash ^= u64::from(b);
        *hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
}

fn main() {
    let mut all = Vec::new();
    for dir in ["src", "shaders"] {
        println!("cargo:rerun-if-changed={dir}");
        files(Path::new(dir), &mut all);
    }
    println!("cargo:rerun-if-changed=build.rs");
    all.sort();
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    for p in &all {
        fnv(&mut hash, p.to_string_lossy().as_bytes());
        fnv(&mut hash, &std::fs::read(p).unwrap_or_default());
    }
    println!("cargo:rustc-env=SCENESAMPLE_SOURCE_HASH={hash:016x}");
}
