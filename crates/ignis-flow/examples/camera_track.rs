//! Tracks a clip's camera against its reference frame (the first, unless a fade in or a
//! soft first frame makes `choose_reference` take a later one, as `ignis loop` does) and
//! prints each frame's view offset
//! (source pixels) and the match's confidence, then a summary: how much of the clip is
//! tracked and how far the view wanders.
//!
//! `cargo run --release -p ignis-flow --example camera_track -- CLIP [EVERY]`

use ignis_flow::camera::{choose_reference, CameraPath, TrackGray, Tracker, REFERENCE_FRAMES};
use ignis_media::DecodedFrame;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(args.get(1).ok_or("usage: camera_track CLIP [EVERY]")?);
    let every: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(25);
    let mut reader = ignis_media::open_keeping_8bit(&path, &Default::default())?;
    let gray = |f: DecodedFrame| match f {
        DecodedFrame::Srgba8 { size, bytes } => TrackGray::from_srgba8(size, &bytes).unwrap(),
        DecodedFrame::Linear(f) => TrackGray::from_rgba(&f),
    };
    let t0 = std::time::Instant::now();
    let mut grays = Vec::new();
    while let Some(f) = reader.next_decoded() {
        grays.push(gray(f?));
    }
    let head = &grays[..grays.len().min(REFERENCE_FRAMES)];
    let r = choose_reference(head).ok_or("no frames")?;
    println!("reference: frame {r}");
    let source = grays[r].source();
    let tracker = Tracker::new(&grays[r]);
    let tracks: Vec<_> = grays.iter().map(|g| tracker.track(g)).collect();
    let secs = t0.elapsed().as_secs_f64();
    for (i, t) in tracks.iter().enumerate().filter(|(i, _)| i % every == 0) {
        println!(
            "{i:5} {:8.3} {:8.3}  peak {:.3} explains {:.3}",
            t.offset[0], t.offset[1], t.peak, t.explains
        );
    }
    let peaks: Vec<f32> = tracks.iter().map(|t| t.peak).collect();
    let mut sorted = peaks.clone();
    sorted.sort_by(f32::total_cmp);
    let n = tracks.len();
    let path = CameraPath { tracks, source };
    println!(
        "{n} frames at {source}: tracked {:.3}, peak min {:.3} median {:.3}, wander {:.2} px, {:.1} ms a frame (decode included)",
        path.tracked_share(),
        sorted[0],
        sorted[n / 2],
        path.wander(),
        secs * 1e3 / n as f64
    );
    match path.decide(false) {
        Ok(s) => println!("auto: steadied, zoom {:.3}", s.zoom),
        Err(why) => println!("auto: left as it is: {why}"),
    }
    Ok(())
}
