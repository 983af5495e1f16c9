//! The committed C header `include/boucwen.h` is what cbindgen generates from
//! `rust/ffi/` with `cbindgen.toml`. With `BOUCWEN_BLESS=1` the test rewrites it.

use std::path::Path;

#[test]
fn committed_header_is_up_to_date() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(root.join("cbindgen.toml")).expect("cbindgen.toml parses");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(root.join("rust/ffi/mod.rs"))
        .generate()
        .expect("cbindgen generates the header")
        .write(&mut generated);
    let generated = String::from_utf8(generated).expect("the header is UTF-8");
    let path = root.join("include/boucwen.h");
    if std::env::var_os("BOUCWEN_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("header written");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/boucwen.h is stale: regenerate it with \
         `BOUCWEN_BLESS=1 cargo test --release --features ffi --test ffi_header`"
    );
}
