//! Puts memory.x on the linker path, and picks the embedded blob and the storage size:
//! `CBD_BLOB` (path of the blob, default `blob.bin` beside this file) and `CBD_STORAGE_LEN`
//! (values of static storage, default 131072; `cbd-fw-host info BLOB` prints what a blob needs).

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(env::var("OUT_DIR").expect("OUT_DIR"));
    fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");

    println!("cargo:rerun-if-env-changed=CBD_BLOB");
    println!("cargo:rerun-if-env-changed=CBD_STORAGE_LEN");
    let blob = env::var_os("CBD_BLOB").map(PathBuf::from).unwrap_or_else(|| manifest.join("blob.bin"));
    let blob = fs::canonicalize(&blob).unwrap_or_else(|e| panic!("blob {}: {e} (set CBD_BLOB)", blob.display()));
    println!("cargo:rerun-if-changed={}", blob.display());
    // include_bytes! needs a literal or env!: hand the path over as a compile-time variable.
    println!("cargo:rustc-env=CBD_BLOB_PATH={}", blob.display());
    let storage: usize = match env::var("CBD_STORAGE_LEN") {
        Ok(s) => s.trim().parse().expect("CBD_STORAGE_LEN must be a number of storage values"),
        Err(_) => 131_072,
    };
    fs::write(out.join("storage_len.rs"), format!("const STORAGE_LEN: usize = {storage};\n")).expect("write storage_len.rs");
}
