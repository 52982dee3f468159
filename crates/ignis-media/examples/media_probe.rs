//! Prints what `probe` says about each argument, then decodes its first 3 frames.
//! Example: `cargo run -p ignis-media --example media_probe -- ../shared/data/candle.mp4`
fn main() {
    for arg in std::env::args().skip(1) {
        let path = std::path::Path::new(&arg);
        match ignis_media::probe(path) {
            Ok(info) => println!("{arg}: {info:?}"),
            Err(e) => println!("{arg}: error: {e}"),
        }
        let opts = ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(0, None)),
            ..Default::default()
        };
        match ignis_media::open(path, &opts) {
            Ok(r) => {
                for (i, f) in r.take(3).enumerate() {
                    match f {
                        Ok(f) => println!(
                            "  frame {i}: {} mean luminance {:.4}",
                            f.size(),
                            f.luminance().mean()
                        ),
                        Err(e) => println!("  frame {i}: error: {e}"),
                    }
                }
            }
            Err(e) => println!("  open: error: {e}"),
        }
    }
}
