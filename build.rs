//! Says so at build time when the AprilTag C library will not be the vendored 3.4.5: the choice
//! is made by `.cargo/config.toml` (`APRILTAG_SRC`), which cargo reads only when it runs inside
//! this repository. Built from elsewhere (`cargo run --manifest-path ...` from another directory)
//! the `apriltag-sys` crate builds its own 3.2.0, which finds fewer tags (the office demo: 183
//! sightings instead of 226) and fails the library's own regression photos.

fn main() {
    println!("cargo:rerun-if-env-changed=APRILTAG_SRC");
    if std::env::var_os("APRILTAG_SRC").is_none() {
        println!(
            "cargo:warning=APRILTAG_SRC is not set, so the AprilTag C library is apriltag-sys's own 3.2.0, not the vendored 3.4.5 (fewer tags found): build from inside the repository, where .cargo/config.toml sets it"
        );
    }
}
