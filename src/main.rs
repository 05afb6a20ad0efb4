//! The `stereotag` command line. Each subcommand lives in its own file under `cli/`.

mod cli;

fn main() {
    keep_freed_memory();
    std::process::exit(cli::main());
}

/// Tells glibc's allocator to keep freed memory for reuse instead of returning it to the system.
/// Its default maps every block over 128 KiB (an image, a detector's buffers) fresh and unmaps it
/// when freed, so each picture of a survey page-faults its buffers in again: 4% of a museum
/// survey's time. Freed blocks are reused now (peak memory stays that of the largest moment).
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; called first thing, before any thread.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 512 << 20);
    }
}
