//! Empty: cargo resolves the build dependencies (Cargo.toml) only for a package that has a
//! build script.
fn main() {}
