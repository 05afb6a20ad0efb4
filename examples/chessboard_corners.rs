//! Prints the chessboard corners stereotag finds in each image as JSON lines
//! (`{"image": ..., "corners": [[x, y], ...]}` or `"miss": reason`), for comparison with OpenCV
//! (`scripts/opencv_chessboard.py --compare`).
//!
//! `cargo run --release --example chessboard_corners -- 9 6 IMAGE...`

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [cols, rows, images @ ..] = args.as_slice() else {
        anyhow::bail!("usage: chessboard_corners COLS ROWS IMAGE...");
    };
    let (cols, rows): (u32, u32) = (cols.parse()?, rows.parse()?);
    for path in images {
        let image = stereotag::io::load_gray(std::path::Path::new(path))?;
        let started = std::time::Instant::now();
        let found = stereotag::calib::chessboard::detect_chessboard(&image, cols, rows);
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let line = match found {
            Ok(corners) => serde_json::json!({"image": path, "ms": ms, "corners": corners}),
            Err(miss) => serde_json::json!({"image": path, "ms": ms, "miss": miss.to_string()}),
        };
        println!("{line}");
    }
    Ok(())
}
