//! Integration tests of `ignis-media`: the shared footage, writer round trips, bad input.
//!
//! Tests needing `../shared/data` or `ffmpeg` print why they skipped and return.

use std::path::{Path, PathBuf};

use ignis_core::palette::srgb_to_linear;
use ignis_media::*;

fn data(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(name);
    if p.exists() {
        Some(p)
    } else {
        println!("skipped: ../shared/data not present");
        None
    }
}

fn have_ffmpeg() -> bool {
    let ok = ffmpeg_available();
    if !ok {
        println!("skipped: ffmpeg/ffprobe not on PATH");
    }
    ok
}

/// A frame whose colours are exact 8-bit sRGB codes and alpha exact 8-bit values, so
/// 8-bit round trips are exact. `alpha` picks opaque or a pattern.
fn test_frame(size: Size, t: u32, alpha: bool) -> RgbaFrame {
    let mut f = RgbaFrame::new(size);
    let (w, h) = (size.width, size.height);
    for y in 0..h {
        for x in 0..w {
            // Smooth gradients plus a moving bright blob: codec-friendly, fire-like.
            let dx = x as f32 - (w as f32 * 0.3 + t as f32 * 1.5);
            let dy = y as f32 - h as f32 * 0.5;
            let blob = (-(dx * dx + dy * dy) / (0.05 * (w * w) as f32)).exp();
            let r = (40.0 + 200.0 * blob + 15.0 * x as f32 / w as f32) as u32;
            let g = (20.0 + 150.0 * blob * blob + 20.0 * y as f32 / h as f32) as u32;
            let b = (10.0 + 40.0 * blob.powi(4)) as u32;
            let a = if alpha {
                [255u32, 128, 64, 0, 200][((x / 3 + y / 2) % 5) as usize]
            } else {
                255
            };
            let c = |v: u32| srgb_to_linear(v.min(255) as f32 / 255.0);
            f.set(x, y, [c(r), c(g), c(b), a as f32 / 255.0]);
        }
    }
    f
}

/// Mean absolute error between two frames in 8-bit sRGB levels (colour only).
fn mae_srgb8(a: &RgbaFrame, b: &RgbaFrame) -> f64 {
    use ignis_core::palette::linear_to_srgb;
    assert_eq!(a.size(), b.size());
    let mut sum = 0.0;
    for (p, q) in a.data().iter().zip(b.data()) {
        for c in 0..3 {
            sum += ((linear_to_srgb(p[c]) - linear_to_srgb(q[c])) * 255.0).abs() as f64;
        }
    }
    sum / (a.data().len() * 3) as f64
}

fn write_all(path: &Path, frames: &[RgbaFrame], opts: &WriteOptions) -> Vec<PathBuf> {
    let mut w = create(path, frames[0].size(), opts).unwrap();
    for f in frames {
        w.push(f).unwrap();
    }
    w.finish().unwrap()
}

fn read_all(path: &Path) -> Vec<RgbaFrame> {
    open(path, &ReadOptions::default())
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap()
}

/// Every frame of `path` decoded by ffmpeg (with `decoder` first, if given) as 8-bit
/// RGBA.
fn ffmpeg_rgba(path: &Path, decoder: Option<&str>, size: Size) -> Vec<Vec<u8>> {
    let mut cmd = std::process::Command::new("ffmpeg");
    cmd.args(["-v", "error"]);
    if let Some(d) = decoder {
        cmd.args(["-c:v", d]);
    }
    let out = cmd
        .arg("-i")
        .arg(path)
        .args(["-f", "rawvideo", "-pix_fmt", "rgba", "-"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
        .chunks_exact(size.pixels() * 4)
        .map(<[u8]>::to_vec)
        .collect()
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

mod footage {
    use super::*;

    #[test]
    fn candle_pure_cargo_path_counts_796_frames() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let info = probe(&path).unwrap();
        assert_eq!(info.decoder, Decoder::Openh264);
        assert_eq!(info.size, Size::new(480, 480).unwrap());
        assert_eq!(info.frame_count, Some(796));
        assert!((info.fps - 30.0).abs() < 0.1, "fps {}", info.fps);
        assert!(
            info.codec.starts_with("h264 (") && info.codec.contains("Baseline"),
            "{}",
            info.codec
        );
        let mut n = 0;
        for f in open(&path, &ReadOptions::default()).unwrap() {
            assert_eq!(f.unwrap().size(), info.size);
            n += 1;
        }
        assert_eq!(n, 796);
    }

    #[test]
    fn candle_range_seeks_to_the_same_frames() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let seq: Vec<RgbaFrame> = open(
            &path,
            &ReadOptions {
                range: Some(FrameRange::frames(0, Some(95))),
                ..Default::default()
            },
        )
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
        assert_eq!(seq.len(), 95);
        let opts = ReadOptions {
            range: Some(FrameRange::frames(90, Some(95))),
            ..Default::default()
        };
        let reader = open(&path, &opts).unwrap();
        assert_eq!(reader.info().frame_count, Some(5));
        let ranged: Vec<RgbaFrame> = reader.collect::<Result<_, _>>().unwrap();
        assert_eq!(ranged.len(), 5);
        for (a, b) in ranged.iter().zip(&seq[90..]) {
            assert_eq!(a, b);
        }
        // Seconds: 1.0 s .. 1.1 s at 30 fps = frames 30, 31, 32.
        let opts = ReadOptions {
            range: Some(FrameRange::seconds(1.0, Some(1.1))),
            ..Default::default()
        };
        let r = open(&path, &opts).unwrap();
        assert_eq!(r.position(), 30);
        assert_eq!(r.count(), 3);
    }

    /// `open_keeping_8bit` + `next_decoded`: the OpenH264 path hands over its 8-bit sRGB
    /// bytes, which convert to exactly the frames `open`'s iterator yields; a crop is cut
    /// from the bytes (equal to `open` with the same crop); with a scale the frame comes
    /// linear.
    #[test]
    fn candle_kept_8bit_converts_to_the_linear_frames() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let range = || Some(FrameRange::frames(3, Some(7)));
        let opts = ReadOptions {
            range: range(),
            ..Default::default()
        };
        let linear: Vec<RgbaFrame> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let mut r = open_keeping_8bit(&path, &opts).unwrap();
        let mut n = 0;
        while let Some(f) = r.next_decoded() {
            let f = f.unwrap();
            let DecodedFrame::Srgba8 { size, bytes } = &f else {
                panic!("frame {n} was converted");
            };
            assert_eq!((*size, bytes.len()), (linear[n].size(), size.pixels() * 4));
            assert_eq!(f.into_linear(), linear[n]);
            n += 1;
        }
        assert_eq!(n, 4);
        let crop = Some(Rect {
            x: 10,
            y: 20,
            width: 30,
            height: 40,
        });
        let opts = ReadOptions {
            range: range(),
            crop,
            ..Default::default()
        };
        let want: Vec<RgbaFrame> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let mut r = open_keeping_8bit(&path, &opts).unwrap();
        for w in &want {
            let f = r.next_decoded().unwrap().unwrap();
            assert!(
                matches!(&f, DecodedFrame::Srgba8 { size, bytes } if *size == w.size() && bytes.len() == size.pixels() * 4),
                "a cropped frame was converted, or cut to the wrong size"
            );
            assert_eq!(&f.into_linear(), w);
        }
        assert!(r.next_decoded().is_none());
        // with a scale as well it comes linear, equal to `open`'s
        let opts = ReadOptions {
            scale: Some(Size::new(15, 20).unwrap()),
            ..opts
        };
        let want: Vec<RgbaFrame> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let mut r = open_keeping_8bit(&path, &opts).unwrap();
        for w in &want {
            match r.next_decoded().unwrap().unwrap() {
                DecodedFrame::Linear(f) => assert_eq!(&f, w),
                DecodedFrame::Srgba8 { .. } => panic!("a scaled frame stayed 8-bit"),
            }
        }
    }

    /// The same through ffmpeg (a clip the built-in decoder does not take): ffmpeg pipes
    /// 8-bit RGBA, which `open_keeping_8bit` hands over as it is; it converts to exactly
    /// the frames `open` yields.
    #[test]
    fn ffmpeg_kept_8bit_converts_to_the_linear_frames() {
        if !ignis_media::ffmpeg_available() {
            println!("skipped: ffmpeg/ffprobe not on PATH");
            return;
        }
        let t = tempfile::tempdir().unwrap();
        let path = t.path().join("clip.mkv");
        let ok = std::process::Command::new("ffmpeg")
            .args([
                "-loglevel",
                "error",
                "-f",
                "lavfi",
                "-i",
                "testsrc=size=64x48:rate=10",
            ])
            .args(["-frames:v", "6", "-c:v", "mpeg4", "-y"])
            .arg(&path)
            .status()
            .unwrap();
        assert!(ok.success());
        let opts = ReadOptions::default();
        let linear: Vec<RgbaFrame> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(linear.len(), 6);
        let mut r = open_keeping_8bit(&path, &opts).unwrap();
        let mut n = 0;
        while let Some(f) = r.next_decoded() {
            let f = f.unwrap();
            assert!(
                matches!(f, DecodedFrame::Srgba8 { .. }),
                "frame {n} was converted"
            );
            assert_eq!(f.into_linear(), linear[n]);
            n += 1;
        }
        assert_eq!(n, 6);
    }

    #[test]
    fn candle_crop_and_scale() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let opts = ReadOptions {
            range: Some(FrameRange::frames(0, Some(2))),
            crop: Some(Rect {
                x: 100,
                y: 50,
                width: 200,
                height: 300,
            }),
            scale: Some(Size::new(50, 75).unwrap()),
        };
        let r = open(&path, &opts).unwrap();
        assert_eq!(r.info().size, Size::new(50, 75).unwrap());
        assert_eq!(r.source_info().size, Size::new(480, 480).unwrap());
        let frames: Vec<_> = r.collect::<Result<_, _>>().unwrap();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].size(), Size::new(50, 75).unwrap());
        let bad = ReadOptions {
            crop: Some(Rect {
                x: 400,
                y: 0,
                width: 100,
                height: 10,
            }),
            ..Default::default()
        };
        assert!(matches!(
            open(&path, &bad),
            Err(MediaError::BadParameter { name: "crop", .. })
        ));
    }

    #[test]
    fn candle_range_errors() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let empty = ReadOptions {
            range: Some(FrameRange::frames(10, Some(10))),
            ..Default::default()
        };
        let e = open(&path, &empty).err().unwrap();
        assert!(e.to_string().contains("empty range"), "{e}");
        let past = ReadOptions {
            range: Some(FrameRange::frames(790, Some(800))),
            ..Default::default()
        };
        let e = open(&path, &past).err().unwrap();
        assert!(e.to_string().contains("past the end"), "{e}");
    }

    #[test]
    fn campfire_through_ffmpeg() {
        let Some(path) = data("campfire.mp4") else {
            return;
        };
        if !have_ffmpeg() {
            return;
        }
        let info = probe(&path).unwrap();
        assert_eq!(info.decoder, Decoder::Ffmpeg);
        assert_eq!(info.size, Size::new(960, 540).unwrap());
        assert_eq!(info.frame_count, Some(512));
        assert!((info.fps - 25.0).abs() < 0.01, "fps {}", info.fps);
        assert!(info.codec.contains("High"), "{}", info.codec);
        let opts = ReadOptions {
            range: Some(FrameRange::frames(100, Some(103))),
            ..Default::default()
        };
        let frames: Vec<_> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(frames.len(), 3);
        let lum = frames[0].luminance();
        assert!(
            lum.max() > 0.2,
            "campfire frame should have bright flames, max {}",
            lum.max()
        );
        assert!(
            lum.mean() < 0.5,
            "and a dark night background, mean {}",
            lum.mean()
        );
        // An accurate seek: frame 101 alone equals the second frame of 100..103.
        let opts = ReadOptions {
            range: Some(FrameRange::frames(101, Some(102))),
            ..Default::default()
        };
        let one: Vec<_> = open(&path, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(one.len(), 1);
        assert!(mae_srgb8(&one[0], &frames[1]) < 0.01);
        // Past the end is caught from ffprobe's frame count.
        let past = ReadOptions {
            range: Some(FrameRange::frames(500, Some(600))),
            ..Default::default()
        };
        assert!(open(&path, &past).is_err());
    }
}

mod probing {
    use super::*;

    /// Makes a 12-frame 64x48 clip with the system ffmpeg; None if this ffmpeg lacks the codec.
    fn make(dir: &Path, name: &str, args: &[&str]) -> Option<PathBuf> {
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=64x48:rate=10",
            "-frames:v",
            "12",
        ];
        make_from(dir, name, &inputs, args)
    }

    /// Makes `name` in `dir` from ffmpeg `inputs` (and their options) encoded with `args`;
    /// None if this ffmpeg cannot.
    fn make_from(dir: &Path, name: &str, inputs: &[&str], args: &[&str]) -> Option<PathBuf> {
        let out = dir.join(name);
        let ok = std::process::Command::new("ffmpeg")
            .args(["-nostdin", "-y", "-v", "error"])
            .args(inputs)
            .args(args)
            .arg(&out)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            println!("skipped {name}: this ffmpeg cannot encode it");
        }
        ok.then_some(out)
    }

    /// Frame times come from the MP4 sample table on the built-in path and from the
    /// packets through ffmpeg: 40 frames of a 30-fps clip with frames 10..20 held twice as
    /// long (every other one dropped, timestamps kept, as a phone in low light) are variable
    /// at 30 fps nominal by both, with exactly the 5 long steps uneven; a constant rate is
    /// not, in MP4 and in Matroska's 1-ms time base (29.97 fps: 33- and 34-ms steps).
    #[test]
    fn frame_times_find_a_variable_rate_on_both_paths() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let src = [
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=64x48:rate=30",
            "-frames:v",
            "40",
        ];
        let vfr = [
            "-vf",
            "select='lt(n\\,10)+gte(n\\,20)+not(mod(n\\,2))'",
            "-fps_mode",
            "vfr",
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
        ];
        for (name, profile, decoder) in [
            ("base.mp4", "baseline", Decoder::Openh264),
            ("high.mp4", "high", Decoder::Ffmpeg),
        ] {
            let mut args = vfr.to_vec();
            args.extend(["-profile:v", profile]);
            let Some(p) = make_from(dir.path(), name, &src, &args) else {
                continue;
            };
            assert_eq!(probe(&p).unwrap().decoder, decoder, "{name}");
            let t = frame_timing(&p).unwrap().expect("frame times");
            assert_eq!(t.len(), 40, "{name}");
            assert_eq!(t.nominal_fps(), 30.0, "{name}");
            assert_eq!(
                t.uneven_steps(),
                vec![10, 11, 12, 13, 14],
                "{name}: {:?}",
                t.steps()
            );
            // 39 steps over source frames 0..=44
            assert!(
                (t.average_fps() - 39.0 * 30.0 / 44.0).abs() < 0.01,
                "{name}"
            );
        }
        for (name, rate) in [("cfr.mp4", "30"), ("cfr.mkv", "30000/1001")] {
            let Some(p) = make_from(
                dir.path(),
                name,
                &[
                    "-f",
                    "lavfi",
                    "-i",
                    &format!("testsrc=size=64x48:rate={rate}"),
                    "-frames:v",
                    "40",
                ],
                &["-c:v", "libx264", "-pix_fmt", "yuv420p"],
            ) else {
                continue;
            };
            let t = frame_timing(&p).unwrap().expect("frame times");
            assert_eq!(t.len(), 40, "{name}");
            assert!(!t.is_variable(), "{name}: {:?}", t.steps());
        }
        // no times to read: a PNG sequence and a GIF
        let seq = dir.path().join("seq");
        std::fs::create_dir_all(&seq).unwrap();
        for i in 0..3 {
            write_png(
                &seq.join(format!("{i:02}.png")),
                &test_frame(Size::new(8, 8).unwrap(), i, false),
            )
            .unwrap();
        }
        assert!(frame_timing(&seq).unwrap().is_none());
        if let Some(g) = make(dir.path(), "x.gif", &[]) {
            assert!(frame_timing(&g).unwrap().is_none());
        }
    }

    #[test]
    fn decoder_is_chosen_by_content_not_extension() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, &[&str], Decoder, &str); 6] = [
            (
                "base.mp4",
                &[
                    "-pix_fmt",
                    "yuv420p",
                    "-c:v",
                    "libx264",
                    "-profile:v",
                    "baseline",
                ],
                Decoder::Openh264,
                "Baseline",
            ),
            (
                "main.mp4",
                &[
                    "-pix_fmt",
                    "yuv420p",
                    "-c:v",
                    "libx264",
                    "-profile:v",
                    "main",
                ],
                Decoder::Ffmpeg,
                "h264 (Main)",
            ),
            // An AVI (MJPEG) misnamed .mp4 still goes to ffmpeg.
            (
                "avi-named.mp4",
                &["-c:v", "mjpeg", "-f", "avi"],
                Decoder::Ffmpeg,
                "mjpeg",
            ),
            ("clip.webm", &["-c:v", "libvpx-vp9"], Decoder::Ffmpeg, "vp9"),
            // Matroska and WebM never store a frame count: it is counted.
            (
                "vp8.webm",
                &[
                    "-c:v",
                    "libvpx",
                    "-auto-alt-ref",
                    "1",
                    "-lag-in-frames",
                    "8",
                ],
                Decoder::Ffmpeg,
                "vp8",
            ),
            (
                "clip.mkv",
                &["-pix_fmt", "yuv420p", "-c:v", "libx264"],
                Decoder::Ffmpeg,
                "h264",
            ),
        ];
        for (name, args, decoder, codec) in cases {
            let Some(path) = make(dir.path(), name, args) else {
                continue;
            };
            let info = probe(&path).unwrap();
            assert_eq!(info.decoder, decoder, "{name}: {info:?}");
            assert_eq!(
                info.frame_count,
                Some(12),
                "{name}: the frame count is known"
            );
            assert!(info.codec.contains(codec), "{name}: {}", info.codec);
            assert_eq!(info.size, Size::new(64, 48).unwrap());
            let frames = read_all(&path);
            assert_eq!(frames.len(), 12, "{name}");
            // A range gives its frames once each, in order: ffmpeg's default frame-rate
            // mode filled the half frame the seek starts early with a copy of the first
            // frame (5, 5, 6, … for 5..9), shifting every frame after it by one.
            let opts = ReadOptions {
                range: Some(FrameRange::frames(5, Some(9))),
                ..Default::default()
            };
            let four: Vec<_> = open(&path, &opts)
                .unwrap()
                .collect::<Result<_, _>>()
                .unwrap();
            assert_eq!(four.len(), 4, "{name}");
            for (i, f) in four.iter().enumerate() {
                let own = mae_srgb8(f, &frames[5 + i]);
                assert!(
                    own < 0.01,
                    "{name}: frame {} of the range is another frame ({own})",
                    5 + i
                );
                for j in [4 + i, 6 + i] {
                    let other = mae_srgb8(f, &frames[j]);
                    assert!(
                        other > 2.0 * own + 1e-4,
                        "{name}: frame {} of the range is as close to frame {j} ({other} against {own})",
                        5 + i
                    );
                }
            }
        }
    }

    /// Clips with a sound track (as nearly all real footage has) read from a frame: each
    /// frame once, in order. Before `-fps_mode passthrough`, ffmpeg filled the half frame
    /// the accurate seek starts early with a copy of the first frame (5, 5, 6, 7); before
    /// seeking by the frames' own timestamps, a variable-rate clip's reads started frames
    /// off; before containers without an index were read from their start, an MPEG-TS read
    /// no frame or started at the next keyframe, and an AVI with B-frames two frames early.
    #[test]
    fn a_range_of_a_clip_with_sound_gives_each_frame_once() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, &[&str]); 6] = [
            (
                "main.mp4",
                &[
                    "-pix_fmt",
                    "yuv420p",
                    "-c:v",
                    "libx264",
                    "-profile:v",
                    "main",
                    "-c:a",
                    "aac",
                ],
            ),
            ("clip.webm", &["-c:v", "libvpx", "-c:a", "libvorbis"]),
            ("clip.mov", &["-c:v", "mjpeg", "-c:a", "pcm_s16le"]),
            // MPEG-TS (a camcorder's .mts, a screen recording) has no index: ffmpeg's seek
            // found no frame after the single keyframe, or a keyframe after the time
            (
                "clip.ts",
                &[
                    "-pix_fmt", "yuv420p", "-c:v", "libx264", "-c:a", "aac", "-f", "mpegts",
                ],
            ),
            // H.264 with B-frames in AVI: no presentation times, frames two behind the rate
            (
                "clip.avi",
                &[
                    "-pix_fmt",
                    "yuv420p",
                    "-c:v",
                    "libx264",
                    "-c:a",
                    "libmp3lame",
                ],
            ),
            // Variable frame rate, as phones record in low light: 25 fps, then from frame 6
            // each frame held twice as long (frame k is not at k / the average rate).
            (
                "vfr.mp4",
                &[
                    "-vf",
                    "setpts='if(lt(N,6),N,6+(N-6)*2)/25/TB'",
                    "-fps_mode",
                    "vfr",
                    "-pix_fmt",
                    "yuv420p",
                    "-c:v",
                    "libx264",
                    "-profile:v",
                    "high",
                    "-c:a",
                    "aac",
                ],
            ),
        ];
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=64x48:rate=25",
            "-f",
            "lavfi",
            "-i",
            "sine=frequency=440:sample_rate=48000",
            "-frames:v",
            "16",
            "-shortest",
        ];
        for (name, args) in cases {
            let Some(out) = make_from(dir.path(), name, &inputs, args) else {
                continue;
            };
            assert_eq!(probe(&out).unwrap().decoder, Decoder::Ffmpeg, "{name}");
            let frames = read_all(&out);
            for start in [1u64, 5, 9] {
                let opts = ReadOptions {
                    range: Some(FrameRange::frames(start, Some(start + 4))),
                    ..Default::default()
                };
                let got: Vec<_> = open(&out, &opts)
                    .unwrap()
                    .collect::<Result<_, _>>()
                    .unwrap();
                assert_eq!(got.len(), 4, "{name} from {start}");
                for (i, f) in got.iter().enumerate() {
                    let k = start as usize + i;
                    let own = mae_srgb8(f, &frames[k]);
                    let next = mae_srgb8(f, &frames[k + 1]);
                    let prev = mae_srgb8(f, &frames[k - 1]);
                    assert!(
                        own < 0.01 && own * 2.0 + 1e-4 < next.min(prev),
                        "{name}: frame {k} read from {start} is not frame {k} (own {own}, previous {prev}, next {next})"
                    );
                }
            }
        }
    }

    /// An AVI's header count is an estimate: `ffmpeg -shortest` writes one that states a
    /// frame more than the file holds. Its frames are counted from its packets, so the
    /// whole clip reads (it used to fail at its end, "the stream ended at frame 60 before
    /// the end of the range (61)"), and the count is the frames read.
    #[test]
    fn an_avi_whose_header_overstates_its_frames_reads_whole() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=64x48:rate=30",
            "-f",
            "lavfi",
            "-i",
            "sine=frequency=440:sample_rate=48000",
            "-t",
            "2",
            "-shortest",
        ];
        // MP3 sound, the AVI muxer's default (with PCM the count comes out right)
        let args = ["-c:v", "mpeg4", "-c:a", "libmp3lame"];
        let Some(avi) = make_from(dir.path(), "clip.avi", &inputs, &args) else {
            return;
        };
        let info = probe(&avi).unwrap();
        assert_eq!(info.decoder, Decoder::Ffmpeg);
        let frames = open(&avi, &ReadOptions::default())
            .and_then(|r| r.collect::<Result<Vec<_>, _>>())
            .expect("the whole AVI reads");
        assert_eq!(Some(frames.len() as u64), info.frame_count);
        assert!((55..=61).contains(&frames.len()), "{}", frames.len());
    }

    /// A clip trimmed without re-encoding (`ffmpeg -ss … -c copy`, as lossless cutters do)
    /// keeps the frames from the keyframe before the cut in its sample table, with an edit
    /// list that leaves them out: ffmpeg decodes them but shows none. Its frame count is
    /// the frames shown (it used to be the table's, and reading failed at the shown frames'
    /// end), and a range starting anywhere gives the frames a sequential read gives there.
    #[test]
    fn a_clip_trimmed_without_re_encoding_reads_its_shown_frames() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = ["-f", "lavfi", "-i", "testsrc=size=64x48:rate=25"];
        // High with B-frames (ffmpeg's path) and Baseline (the built-in decoder's, which
        // hands a trimmed clip to ffmpeg)
        for profile in ["high", "baseline"] {
            let args = [
                "-frames:v",
                "100",
                "-pix_fmt",
                "yuv420p",
                "-c:v",
                "libx264",
                "-profile:v",
                profile,
                "-g",
                "25",
            ];
            let Some(whole) = make_from(dir.path(), &format!("{profile}.mp4"), &inputs, &args)
            else {
                return;
            };
            let trimmed = dir.path().join(format!("{profile}-trimmed.mp4"));
            let ok = std::process::Command::new("ffmpeg")
                .args(["-nostdin", "-y", "-v", "error", "-ss", "1.5", "-i"])
                .arg(&whole)
                .args(["-t", "2", "-c", "copy"])
                .arg(&trimmed)
                .status()
                .is_ok_and(|s| s.success());
            if !ok {
                println!("skipped: this ffmpeg cannot stream-copy the clip");
                return;
            }
            let info = probe(&trimmed).unwrap();
            assert_eq!(info.decoder, Decoder::Ffmpeg, "{profile}");
            let frames = open(&trimmed, &ReadOptions::default())
                .and_then(|r| r.collect::<Result<Vec<_>, _>>())
                .expect("the trimmed clip reads whole");
            assert_eq!(Some(frames.len() as u64), info.frame_count);
            // about 2 s at 25 fps, not the ~12 more frames of pre-roll its table lists
            assert!((48..=56).contains(&frames.len()), "{}", frames.len());
            // its first frame is the whole clip's first at or after 1.5 s (frame 38, 1.52 s),
            // not the keyframe at 1 s the pre-roll starts from
            let source = read_all(&whole);
            let at = |f: &RgbaFrame| {
                (0..source.len())
                    .min_by(|&a, &b| mae_srgb8(f, &source[a]).total_cmp(&mae_srgb8(f, &source[b])))
                    .unwrap()
            };
            assert_eq!(at(&frames[0]), 38, "{profile}: the first frame shown");
            for start in [1u64, 9, 30] {
                let opts = ReadOptions {
                    range: Some(FrameRange::frames(start, Some(start + 4))),
                    ..Default::default()
                };
                let got: Vec<_> = open(&trimmed, &opts)
                    .unwrap()
                    .collect::<Result<_, _>>()
                    .unwrap();
                assert_eq!(got.len(), 4, "{profile} from {start}");
                for (i, f) in got.iter().enumerate() {
                    let k = start as usize + i;
                    let e = mae_srgb8(f, &frames[k]);
                    assert!(e < 0.01, "{profile}: frame {k} read from {start}, {e} off");
                }
            }
        }
    }

    /// A clip read through ffmpeg whose data stops before the frame count its header
    /// promises (an incomplete download: the index at the front, the frames cut off) fails
    /// at the frame where it ends, and the error says the file may be cut short and what
    /// to do, not only that a range was not reached (the user asked for none).
    #[test]
    fn a_clip_cut_short_says_it_may_be_truncated() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = ["-f", "lavfi", "-i", "testsrc=size=64x48:rate=25"];
        let args = [
            "-frames:v",
            "40",
            "-pix_fmt",
            "yuv420p",
            "-c:v",
            "libx264",
            "-profile:v",
            "high",
            "-movflags",
            "+faststart",
        ];
        let Some(whole) = make_from(dir.path(), "whole.mp4", &inputs, &args) else {
            return;
        };
        assert_eq!(probe(&whole).unwrap().decoder, Decoder::Ffmpeg);
        let bytes = std::fs::read(&whole).unwrap();
        // cut in its header, in its first frames (ffmpeg fails on a partial packet) and
        // near its end (the frames stop early)
        for percent in [20, 40, 60, 80, 95, 99] {
            let cut = dir.path().join(format!("cut{percent}.mp4"));
            std::fs::write(&cut, &bytes[..bytes.len() * percent / 100]).unwrap();
            let e = open(&cut, &ReadOptions::default())
                .and_then(|r| r.collect::<Result<Vec<_>, _>>())
                .expect_err("a clip cut short must not read as whole");
            let m = e.to_string();
            assert!(
                m.contains("may be truncated") && m.contains("copy it again"),
                "{percent} %: {m}"
            );
        }
    }

    /// Copies the clip `from` to `to` with a quarter-turn display rotation, as a phone
    /// records a portrait clip (the stream copy's display matrix, ffmpeg ≥ 5); false if
    /// this ffmpeg cannot.
    fn turned_copy(from: &Path, to: &Path) -> bool {
        std::process::Command::new("ffmpeg")
            .args(["-nostdin", "-y", "-v", "error", "-i"])
            .arg(from)
            .args(["-c", "copy", "-metadata:s:v:0", "rotate=90"])
            .arg(to)
            .status()
            .is_ok_and(|s| s.success())
    }

    /// A phone's portrait clip: stored 64x48 with a quarter-turn display rotation. It is
    /// read upright (48x64, through ffmpeg, whose frames match the same picture encoded
    /// upright), never sideways through the built-in decoder.
    #[test]
    fn rotated_clips_are_read_upright() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let x264 = [
            "-pix_fmt",
            "yuv420p",
            "-c:v",
            "libx264",
            "-profile:v",
            "baseline",
        ];
        let upright = [&["-vf", "transpose=cclock"][..], &x264[..]].concat();
        let (Some(stored), Some(upright)) = (
            make(dir.path(), "stored.mp4", &x264),
            make(dir.path(), "upright.mp4", &upright),
        ) else {
            return;
        };
        let turned = dir.path().join("turned.mp4");
        if !turned_copy(&stored, &turned) {
            println!("skipped: this ffmpeg cannot set a display rotation");
            return;
        }
        let info = probe(&turned).unwrap();
        assert_eq!(info.size, Size::new(48, 64).unwrap(), "{info:?}");
        assert_eq!(info.decoder, Decoder::Ffmpeg);
        let (a, b) = (read_all(&turned), read_all(&upright));
        assert_eq!(a.len(), 12);
        assert_eq!(a[0].size(), Size::new(48, 64).unwrap());
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            let e = mae_srgb8(x, y);
            assert!(e < 8.0, "frame {k}: {e} levels from the upright picture");
        }
    }

    /// The bounding box (width, height) of the pixels brighter than half white.
    fn bright_box(f: &RgbaFrame) -> (u32, u32) {
        let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
        for y in 0..f.height() {
            for (x, p) in f.row(y).iter().enumerate() {
                if p[1] > 0.5 {
                    (x0, y0) = (x0.min(x as u32), y0.min(y));
                    (x1, y1) = (x1.max(x as u32), y1.max(y));
                }
            }
        }
        assert!(x1 >= x0, "no bright pixel");
        (x1 - x0 + 1, y1 - y0 + 1)
    }

    /// Non-square pixels (anamorphic DV/HDV, some broadcast and phone footage) are read
    /// at square-pixel size, as players show them: a box stored 30×40 with 4:3 pixels is
    /// 40×40. Through the pure path (the SAR from the SPS's VUI) and ffmpeg (ffprobe's),
    /// with a display rotation (which turns the pixels too), and with crops given in the
    /// shown size.
    #[test]
    fn anamorphic_clips_are_read_at_square_pixels() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "color=black:s=96x72:r=10,drawbox=x=24:y=16:w=30:h=40:color=white:t=fill,setsar=4/3",
            "-frames:v",
            "6",
        ];
        let x264 = |profile| {
            [
                "-pix_fmt",
                "yuv420p",
                "-c:v",
                "libx264",
                "-profile:v",
                profile,
            ]
        };
        let (Some(base), Some(high)) = (
            make_from(dir.path(), "base.mp4", &inputs, &x264("baseline")),
            make_from(dir.path(), "high.mp4", &inputs, &x264("high")),
        ) else {
            return;
        };
        let turned = dir.path().join("turned.mp4");
        let ok = turned_copy(&high, &turned);
        let stored = Size::new(96, 72).unwrap();
        let mut cases = vec![
            (
                &base,
                Decoder::Openh264,
                Size::new(128, 72).unwrap(),
                (4, 3),
                stored,
            ),
            (
                &high,
                Decoder::Ffmpeg,
                Size::new(128, 72).unwrap(),
                (4, 3),
                stored,
            ),
        ];
        if ok {
            let upright = Size::new(72, 96).unwrap();
            cases.push((
                &turned,
                Decoder::Ffmpeg,
                Size::new(72, 128).unwrap(),
                (3, 4),
                upright,
            ));
        } else {
            println!("skipped the rotated case: this ffmpeg cannot set a display rotation");
        }
        for (path, decoder, shown, aspect, stored) in cases {
            let info = probe(path).unwrap();
            assert_eq!(info.decoder, decoder, "{info:?}");
            assert_eq!(info.size, shown, "{info:?}");
            let a = info.anamorphic.expect("anamorphic");
            assert_eq!((a.stored, a.pixel_aspect), (stored, aspect));
            let frames = read_all(path);
            assert_eq!(frames.len(), 6);
            for f in &frames {
                assert_eq!(f.size(), shown);
                let (w, h) = bright_box(f);
                assert!(
                    w.abs_diff(40) <= 2 && h.abs_diff(40) <= 2,
                    "{path:?}: box {w}x{h}"
                );
            }
        }
        // A crop is in the shown size: the right half of the 128-wide picture.
        let opts = ReadOptions {
            crop: Some(Rect {
                x: 64,
                y: 0,
                width: 64,
                height: 72,
            }),
            ..Default::default()
        };
        for path in [&base, &high] {
            let f = open(path, &opts).unwrap().next().unwrap().unwrap();
            assert_eq!(f.size(), Size::new(64, 72).unwrap());
            // The box spans shown columns 32..72, so 8 of its columns are in the crop.
            let (w, h) = bright_box(&f);
            assert!(
                w.abs_diff(8) <= 2 && h.abs_diff(40) <= 2,
                "{path:?}: {w}x{h}"
            );
        }
    }

    /// A file whose first video stream is a still (a cover or a poster frame muxed as a
    /// one-frame stream) reads as the clip, the stream ffmpeg itself would pick.
    #[test]
    fn the_clip_is_read_not_a_still_before_it() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let x264 = ["-pix_fmt", "yuv420p", "-c:v", "libx264"];
        let poster_in = ["-f", "lavfi", "-i", "color=red:s=32x32", "-frames:v", "1"];
        let (Some(clip), Some(poster)) = (
            make(dir.path(), "clip.mp4", &x264),
            make_from(dir.path(), "poster.png", &poster_in, &[]),
        ) else {
            return;
        };
        let inputs = ["-i", poster.to_str().unwrap(), "-i", clip.to_str().unwrap()];
        let args = [
            "-map", "0:v", "-map", "1:v", "-c:v:0", "mjpeg", "-c:v:1", "copy", "-f", "matroska",
        ];
        let Some(mkv) = make_from(dir.path(), "poster.mkv", &inputs, &args) else {
            return;
        };
        let info = probe(&mkv).unwrap();
        assert_eq!(info.size, Size::new(64, 48).unwrap(), "{info:?}");
        assert!(info.codec.starts_with("h264"), "{}", info.codec);
        let frames = read_all(&mkv);
        assert_eq!(frames.len(), 12);
        assert!(frames.iter().all(|f| f.size() == info.size));
        // A ranged read seeks in the clip's own timestamps.
        let opts = ReadOptions {
            range: Some(FrameRange::frames(5, Some(8))),
            ..Default::default()
        };
        let part: Vec<_> = open(&mkv, &opts).unwrap().map(Result::unwrap).collect();
        assert_eq!(part.len(), 3);
        assert!(mae_srgb8(&part[0], &frames[5]) < 0.5);
    }

    /// Baseline clips tagged BT.709 or full range (HD cameras, some phones) are read with
    /// their own matrix and range on the pure path too, as ffmpeg reads them: an orange
    /// comes back orange.
    #[test]
    fn pure_path_follows_the_streams_matrix_and_range() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "color=c=0xFF8020:s=64x48:r=10,format=rgb24",
            "-frames:v",
            "2",
        ];
        let cases = [
            ("709.mp4", "bt709", "tv", "yuv420p"),
            ("full.mp4", "bt601", "pc", "yuvj420p"),
            ("601.mp4", "bt601", "tv", "yuv420p"),
        ];
        for (name, matrix, range, fmt) in cases {
            let vf = format!("scale=out_color_matrix={matrix}:out_range={range},format={fmt}");
            let space = if matrix == "bt709" {
                "bt709"
            } else {
                "smpte170m"
            };
            let args = [
                "-vf",
                &vf,
                "-c:v",
                "libx264",
                "-profile:v",
                "baseline",
                "-qp",
                "1",
                "-colorspace",
                space,
                "-color_range",
                range,
            ];
            let Some(clip) = make_from(dir.path(), name, &inputs, &args) else {
                return;
            };
            assert_eq!(probe(&clip).unwrap().decoder, Decoder::Openh264, "{name}");
            let f = &read_all(&clip)[0];
            let p = f.get(32, 24);
            let e = |v: f32| ignis_core::palette::linear_to_srgb(v) * 255.0;
            let got = [e(p[0]), e(p[1]), e(p[2])];
            let off = got
                .iter()
                .zip([255.0, 128.0, 32.0])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            println!("{name}: {got:?}");
            assert!(off < 3.0, "{name}: read {got:?} for (255, 128, 32)");
        }
    }

    /// HDR footage (HLG and PQ, BT.2020: phones record it by default) is read as the SDR
    /// picture it shows, not the washed-out one its raw code values give: a clip made
    /// from an SDR picture with SDR white at the HDR reference white (203 cd/m²) reads
    /// back close to it, and much closer than a plain decode.
    #[test]
    fn hdr_clips_are_read_as_sdr() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        // The SDR picture, exactly (RGB PNGs), and HDR clips made from the same RGB frames
        // (lossless, so only the conversions differ).
        let src = [
            "-f",
            "lavfi",
            "-i",
            "testsrc2=size=96x64:rate=10,format=rgb24",
            "-frames:v",
            "4",
        ];
        let seq = dir.path().join("sdr");
        std::fs::create_dir_all(&seq).unwrap();
        if make_from(&seq, "%02d.png", &src, &[]).is_none() {
            return;
        }
        let reference = read_all(&seq);
        for (name, trc) in [("hlg.mp4", "arib-std-b67"), ("pq.mp4", "smpte2084")] {
            let vf = format!(
                "format=gbrp,zscale=tin=bt709:pin=bt709:min=gbr:rin=full:t=linear:p=bt709:npl=203,\
                 format=gbrpf32le,\
zscale=p=bt2020:t={trc}:m=bt2020nc:r=tv:npl=203,format=yuv444p10le"
            );
            let args = [
                "-vf",
                &vf,
                "-c:v",
                "libx264",
                "-qp",
                "0",
                "-color_trc",
                trc,
                "-color_primaries",
                "bt2020",
                "-colorspace",
                "bt2020nc",
                "-color_range",
                "tv",
            ];
            let Some(hdr) = make_from(dir.path(), name, &src, &args) else {
                continue;
            };
            let info = probe(&hdr).unwrap();
            if info.codec.contains("no zscale") {
                println!("skipped {name}: this ffmpeg has no zscale filter");
                continue;
            }
            assert!(info.codec.contains("read as SDR"), "{}", info.codec);
            let ours = read_all(&hdr);
            let plain = ffmpeg_rgba(&hdr, None, Size::new(96, 64).unwrap());
            assert_eq!((ours.len(), plain.len()), (4, 4));
            for k in 0..4 {
                let e = mae_srgb8(&reference[k], &ours[k]);
                let plain_k = bench_support::srgba8_to_linear(reference[k].size(), &plain[k]);
                let raw = mae_srgb8(&plain_k, &reference[k]);
                println!(
                    "{name} frame {k}: {e:.2} levels from the SDR picture (plain decode {raw:.2})"
                );
                assert!(e < 2.5, "{name} frame {k}: {e:.2} levels");
                assert!(
                    raw > 2.0 * e,
                    "{name}: a plain decode is as close ({raw:.2} vs {e:.2})"
                );
            }
        }
    }

    /// Interlaced footage (broadcast, older cameras) is deinterlaced: a bar moving at 50
    /// fields a second, woven into 25 interlaced frames, is read without combing (rows
    /// alternating between the two fields' pictures).
    #[test]
    fn interlaced_clips_are_deinterlaced() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = [
            "-f",
            "lavfi",
            "-i",
            "color=black:s=96x64:r=50[b];color=white:s=16x64:r=50[w];\
             [b][w]overlay=x='mod(t*400,80)':y=0",
            "-frames:v",
            "24",
        ];
        let args = [
            "-vf",
            "tinterlace=interleave_top,setfield=tff",
            "-c:v",
            "libx264",
            "-qp",
            "0",
            "-pix_fmt",
            "yuv420p",
            "-flags",
            "+ildct+ilme",
            "-x264opts",
            "tff=1",
        ];
        let Some(clip) = make_from(dir.path(), "inter.mp4", &inputs, &args) else {
            return;
        };
        let info = probe(&clip).unwrap();
        if info.codec.contains("no bwdif") {
            println!("skipped: this ffmpeg has no bwdif filter");
            return;
        }
        assert!(info.codec.contains("deinterlaced"), "{}", info.codec);
        // Combing: how far each row is from the mean of its two neighbours (the other
        // field's rows), mean over the picture.
        let comb = |rows: &dyn Fn(u32) -> Vec<f32>, h: u32| {
            let mut across = 0.0;
            for y in 1..h - 1 {
                let (a, b, c) = (rows(y - 1), rows(y), rows(y + 1));
                for x in 0..a.len() {
                    across += (b[x] - 0.5 * (a[x] + c[x])).abs() as f64;
                }
            }
            across / ((h - 2) as f64 * 96.0)
        };
        let ours = read_all(&clip);
        assert_eq!(ours.len(), 24);
        let plain = ffmpeg_rgba(&clip, None, Size::new(96, 64).unwrap());
        let (mut c_ours, mut c_plain) = (0.0, 0.0);
        for (f, p) in ours.iter().zip(&plain) {
            c_ours += comb(&|y| f.row(y).iter().map(|q| q[1]).collect(), 64);
            c_plain += comb(
                &|y| {
                    p[(y * 96 * 4) as usize..((y + 1) * 96 * 4) as usize]
                        .chunks(4)
                        .map(|q| q[1] as f32 / 255.0)
                        .collect()
                },
                64,
            );
        }
        // A ranged read (a loop's, a window's) gives the same frames as the whole read, not
        // frames a field or a frame apart (the bar moves 8 px a field).
        let opts = ReadOptions {
            range: Some(FrameRange::frames(7, Some(11))),
            ..Default::default()
        };
        let part: Vec<_> = open(&clip, &opts).unwrap().map(Result::unwrap).collect();
        assert_eq!(part.len(), 4);
        for (k, f) in part.iter().enumerate() {
            let e = mae_srgb8(f, &ours[7 + k]);
            assert!(
                e < 0.5,
                "ranged frame {}: {e:.3} levels from the whole read",
                7 + k
            );
        }
        println!("combing: read {c_ours:.3}, plain decode {c_plain:.3}");
        assert!(
            c_plain > 4.0 * c_ours,
            "read {c_ours:.3}, plain {c_plain:.3}"
        );
    }
}

mod roundtrip {
    use super::*;

    fn size(w: u32, h: u32) -> Size {
        Size::new(w, h).unwrap()
    }

    #[test]
    fn png_sequence_directory_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..5).map(|t| test_frame(size(17, 13), t, true)).collect();
        let out = dir.path().join("seq/");
        let written = write_all(&out, &frames, &WriteOptions::default());
        assert_eq!(written.len(), 5);
        assert_eq!(
            dir_entries(&dir.path().join("seq")),
            ["0000.png", "0001.png", "0002.png", "0003.png", "0004.png"]
        );
        let info = probe(&out).unwrap();
        assert_eq!(
            (info.decoder, info.frame_count, info.size),
            (Decoder::ImageSequence, Some(5), size(17, 13))
        );
        assert_eq!(read_all(&out), frames);
    }

    /// An EXR sequence states its rate in each frame's `framesPerSecond` and is read back at
    /// it (NTSC rates exactly); a PNG sequence, which cannot, reads at the default.
    #[test]
    fn an_exr_sequence_keeps_its_rate() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..4).map(|t| test_frame(size(8, 6), t, false)).collect();
        for (fps, codec) in [
            (24.0, "exr sequence, 24 fps in its headers"),
            (24000.0 / 1001.0, "exr sequence, 23.976 fps in its headers"),
            (12.5, "exr sequence, 12.5 fps in its headers"),
        ] {
            let seq = dir.path().join(format!("e{fps}"));
            let opts = WriteOptions {
                fps,
                ..WriteOptions::default()
            };
            write_all(&seq.join("f.####.exr"), &frames, &opts);
            for path in [seq.clone(), seq.join("f.%04d.exr")] {
                let info = probe(&path).unwrap();
                assert_eq!(
                    (info.fps, info.codec.as_str()),
                    (fps, codec),
                    "{}",
                    path.display()
                );
                assert!(info.rate_stated, "{}", path.display());
            }
            let png = dir.path().join(format!("p{fps}"));
            write_all(&png.join("%04d.png"), &frames, &opts);
            let info = probe(&png).unwrap();
            assert_eq!((info.fps, info.rate_stated), (DEFAULT_SEQUENCE_FPS, false));
        }
    }

    /// Frames in a format only ffmpeg reads (a DPX plate) are refused with the ffmpeg
    /// command that converts them, keeping their numbers (and where ffmpeg would stop at a
    /// gap); a directory of other files keeps its plain message.
    #[test]
    fn dpx_frames_are_refused_with_the_command_that_converts_them() {
        let dir = tempfile::tempdir().unwrap();
        let plate = dir.path().join("plate");
        std::fs::create_dir(&plate).unwrap();
        // DPX headers only: what matters is that no decoder here reads them
        for n in [1001, 1002, 1004] {
            std::fs::write(plate.join(format!("sh010.{n}.dpx")), b"SDPX\0\0\0\0").unwrap();
        }
        let d = plate.display();
        let e = probe(&plate.join("sh010.####.dpx"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!(
                "unsupported .dpx frames in {d}/sh010.####.dpx: Ignis reads PNG, JPEG, TIFF and EXR \
                 frames; convert these with ffmpeg first: `ffmpeg -start_number 1001 -i \
                 {d}/sh010.%04d.dpx -start_number 1001 {d}/sh010.%04d.png`; it stops before the \
                 missing frame 1003: run it again with -start_number 1004 (both)"
            )),
            "{e}"
        );
        let e = probe(&plate).unwrap_err().to_string();
        assert!(
            e.contains(&format!(
                "`ffmpeg -start_number 1001 -i {d}/sh010.%04d.dpx -start_number 1001 {d}/sh010.%04d.png`"
            )),
            "{e}"
        );
        let e = probe(&plate.join("sh010.%04d.dpx"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("-i ") && e.contains("sh010.%04d.dpx -start_number 1001"),
            "{e}"
        );
        // a scan's levels and log colours are DPX's (and Cineon's) concern, not WebP's
        assert!(e.contains("keeps a 10- or 12-bit scan's levels"), "{e}");
        let web = dir.path().join("web");
        std::fs::create_dir(&web).unwrap();
        for n in [1, 2] {
            std::fs::write(web.join(format!("f{n:02}.webp")), b"RIFF").unwrap();
        }
        let e = probe(&web.join("f%02d.webp")).unwrap_err().to_string();
        assert!(
            e.contains("unsupported .webp frames")
                && e.contains("`ffmpeg -i ")
                && !e.contains("12-bit"),
            "{e}"
        );
        // not frames at all: nothing to convert
        let notes = dir.path().join("notes");
        std::fs::create_dir(&notes).unwrap();
        std::fs::write(notes.join("a.txt"), b"x").unwrap();
        let e = probe(&notes).unwrap_err().to_string();
        assert!(
            e.contains("holds no PNG, JPEG, EXR or TIFF frames") && !e.contains("ffmpeg"),
            "{e}"
        );
    }

    /// A sequence with frames missing (a render farm's lost frame) is read without them,
    /// and says which: the pattern's numbers and a directory's names alike.
    #[test]
    fn a_sequence_says_which_frames_are_missing() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..8).map(|t| test_frame(size(8, 6), t, false)).collect();
        let seq = dir.path().join("seq");
        write_all(&seq.join("f%04d.png"), &frames, &WriteOptions::default());
        assert_eq!(probe(&seq).unwrap().codec, "png sequence");
        for k in [3, 5, 6] {
            std::fs::remove_file(seq.join(format!("f{k:04}.png"))).unwrap();
        }
        for path in [seq.clone(), seq.join("f%04d.png")] {
            let info = probe(&path).unwrap();
            assert_eq!(info.frame_count, Some(5));
            assert_eq!(
                info.codec,
                "png sequence, 3 frames missing (3, 5, 6): read without them, a jump at each gap",
                "{}",
                path.display()
            );
            assert_eq!(read_all(&path).len(), 5);
            // timed by the numbers (frames 0, 1, 2, 4, 7 left): the steps over 3 and over
            // 5, 6 are the uneven ones
            let t = frame_timing(&path).unwrap().expect("a gap's timing");
            assert!(t.from_frame_numbers());
            assert_eq!(t.uneven_steps(), [2, 3], "{:?}", t.steps());
            assert_eq!(t.nominal_fps(), DEFAULT_SEQUENCE_FPS);
            assert_eq!(t.len(), 5);
        }
        // names whose numbers skip more than there are files count something else (a time
        // of day): said, read one frame per file, no timing
        let odd = dir.path().join("odd");
        std::fs::create_dir(&odd).unwrap();
        for (k, n) in [1, 2, 3, 1000].into_iter().enumerate() {
            write_png(&odd.join(format!("t{n}.png")), &frames[k]).unwrap();
        }
        let info = probe(&odd).unwrap();
        assert_eq!(
            info.codec,
            "png sequence, its numbers skip 996, more than it has files (times or takes, not \
             lost frames): read one frame per file"
        );
        assert_eq!(read_all(&odd).len(), 4);
        assert!(frame_timing(&odd).unwrap().is_none());
    }

    #[test]
    fn png_pattern_into_existing_directory_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("notes.txt"), "keep me").unwrap();
        let frames: Vec<_> = (0..3).map(|t| test_frame(size(8, 6), t, true)).collect();
        let pattern = dir.path().join("f_%03d.png");
        write_all(&pattern, &frames, &WriteOptions::default());
        assert_eq!(
            dir_entries(dir.path()),
            ["f_000.png", "f_001.png", "f_002.png", "notes.txt"]
        );
        assert_eq!(read_all(&pattern), frames);
        // A range and scale on a sequence.
        let opts = ReadOptions {
            range: Some(FrameRange::frames(1, None)),
            scale: Some(size(4, 3)),
            ..Default::default()
        };
        let r: Vec<_> = open(&pattern, &opts)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].size(), size(4, 3));
    }

    #[test]
    fn exr_sequence_is_exact_f32() {
        let dir = tempfile::tempdir().unwrap();
        // Alphas that are powers of two make premultiply/unpremultiply exact; HDR values too.
        let frames: Vec<_> = (0..3)
            .map(|t| {
                let mut f = test_frame(size(9, 7), t, false);
                for (i, p) in f.data_mut().iter_mut().enumerate() {
                    p[0] *= 3.7;
                    p[3] = [1.0, 0.5, 0.25][(i + t as usize) % 3];
                }
                f
            })
            .collect();
        let pattern = dir.path().join("exr/%04d.exr");
        write_all(&pattern, &frames, &WriteOptions::default());
        // the rate written (the default 30) is in every header
        assert_eq!(
            probe(&pattern).unwrap().codec,
            "exr sequence, 30 fps in its headers"
        );
        assert_eq!(read_all(&pattern), frames);
    }

    #[test]
    fn gif_roundtrip_within_palette_error() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..8).map(|t| test_frame(size(40, 30), t, false)).collect();
        let path = dir.path().join("fire.gif");
        let opts = WriteOptions {
            fps: 25.0,
            ..Default::default()
        };
        write_all(&path, &frames, &opts);
        let info = probe(&path).unwrap();
        assert_eq!((info.decoder, info.size), (Decoder::Gif, size(40, 30)));
        assert!((info.fps - 25.0).abs() < 1e-9);
        let back = read_all(&path);
        assert_eq!(back.len(), 8);
        for (a, b) in frames.iter().zip(&back) {
            let e = mae_srgb8(a, b);
            println!("gif mean abs error {e:.2} levels");
            // NeuQuant on smooth gradients: documented bound of 3 levels mean abs error.
            assert!(e < 3.0, "gif mean abs error {e:.2} levels");
        }
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            bytes.windows(11).any(|w| w == b"NETSCAPE2.0"),
            "GIF must loop (NETSCAPE extension)"
        );
    }

    /// 30 and 29.97 fps are kept in whole centiseconds by alternating delays (3, 3, 4 cs):
    /// the probe reads the rate over every frame's delay (the first alone says 33.3 fps)
    /// and counts the frames. A truncated GIF still probes: the frames before the cut.
    #[test]
    fn gif_rate_is_read_over_all_delays() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..12)
            .map(|t| test_frame(size(40, 30), t, false))
            .collect();
        for fps in [30.0, 30000.0 / 1001.0, 24.0] {
            let path = dir.path().join(format!("r{fps}.gif"));
            let opts = WriteOptions {
                fps,
                ..Default::default()
            };
            write_all(&path, &frames, &opts);
            let info = probe(&path).unwrap();
            assert_eq!(info.frame_count, Some(12), "{fps}");
            // 12 frames in whole centiseconds: within one centisecond over the clip
            let whole = 12.0 * 100.0 / fps;
            let bound = fps * (1.0 - whole / (whole + 1.0));
            assert!(
                (info.fps - fps).abs() <= bound,
                "{fps}: probed {}",
                info.fps
            );
            if fps == 30.0 {
                assert!((info.fps - 30.0).abs() < 1e-9, "{}", info.fps);
            }
        }
        let bytes = std::fs::read(dir.path().join("r30.gif")).unwrap();
        let cut = dir.path().join("cut.gif");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let info = probe(&cut).unwrap();
        assert_eq!(info.frame_count, None);
        assert!((25.0..=34.0).contains(&info.fps), "{}", info.fps);
    }

    #[test]
    fn gif_composites_alpha_over_background() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bg.gif");
        let f = RgbaFrame::filled(size(6, 4), [1.0, 1.0, 1.0, 0.0]);
        let opts = WriteOptions {
            background: [0.0, 0.0, 1.0],
            ..Default::default()
        };
        write_all(&path, &[f], &opts);
        let back = read_all(&path);
        let p = back[0].get(2, 2);
        assert!(p[0] < 0.01 && p[2] > 0.99 && p[3] == 1.0, "{p:?}");
    }

    #[test]
    fn mp4_roundtrip_via_pure_path() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..30)
            .map(|t| test_frame(size(64, 48), t, false))
            .collect();
        let path = dir.path().join("fire.mp4");
        write_all(&path, &frames, &WriteOptions::default());
        assert_eq!(dir_entries(dir.path()), ["fire.mp4"]);
        let info = probe(&path).unwrap();
        assert_eq!(info.decoder, Decoder::Openh264, "{info:?}");
        assert_eq!((info.size, info.frame_count), (size(64, 48), Some(30)));
        assert!((info.fps - 30.0).abs() < 1e-6, "fps {}", info.fps);
        let back = read_all(&path);
        assert_eq!(back.len(), 30);
        let worst = frames
            .iter()
            .zip(&back)
            .map(|(a, b)| mae_srgb8(a, b))
            .fold(0.0, f64::max);
        println!(
            "mp4 worst mean abs error {worst:.2} levels, {} bytes",
            std::fs::metadata(&path).unwrap().len()
        );
        // H.264 at 0.3 bit/pixel plus 4:2:0 chroma: documented bound of 4 levels mean abs error.
        assert!(worst < 4.0, "mp4 mean abs error {worst:.2} levels");
        ffprobe_checks(&path, 64, 48, 30);
    }

    #[test]
    fn mp4_pads_odd_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..4).map(|t| test_frame(size(33, 21), t, false)).collect();
        let path = dir.path().join("odd.mp4");
        let mut w = create(&path, size(33, 21), &WriteOptions::default()).unwrap();
        assert_eq!(w.output_size(), size(34, 22));
        for f in &frames {
            w.push(f).unwrap();
        }
        w.finish().unwrap();
        let back = read_all(&path);
        assert_eq!((back.len(), back[0].size()), (4, size(34, 22)));
        // The padding repeats the last column.
        let (a, b) = (back[0].get(32, 5), back[0].get(33, 5));
        assert!((a[0] - b[0]).abs() < 0.05, "{a:?} {b:?}");
        ffprobe_checks(&path, 34, 22, 4);
    }

    /// Largest difference of alpha, and mean colour error (8-bit sRGB levels, where both
    /// are at least half opaque), of decoded 8-bit RGBA against the frames written.
    fn alpha_and_colour_error(frames: &[RgbaFrame], back: &[Vec<u8>]) -> (f32, f64) {
        use ignis_core::palette::linear_to_srgb;
        let (mut worst_alpha, mut sum, mut n) = (0f32, 0f64, 0u64);
        for (f, b) in frames.iter().zip(back) {
            assert_eq!(b.len(), f.data().len() * 4);
            for (p, q) in f.data().iter().zip(b.chunks_exact(4)) {
                worst_alpha = worst_alpha.max((p[3] * 255.0 - q[3] as f32).abs());
                if p[3] >= 0.5 && q[3] >= 128 {
                    for c in 0..3 {
                        sum += (linear_to_srgb(p[c]) * 255.0 - q[c] as f32).abs() as f64;
                    }
                    n += 3;
                }
            }
        }
        (worst_alpha, sum / n.max(1) as f64)
    }

    #[test]
    fn mov_is_prores_4444_with_alpha() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        // Odd sides and an alpha pattern with holes: nothing padded, alpha kept.
        let frames: Vec<_> = (0..6).map(|t| test_frame(size(33, 17), t, true)).collect();
        let path = dir.path().join("fire.mov");
        let opts = WriteOptions {
            fps: 30000.0 / 1001.0,
            ..Default::default()
        };
        let written = write_all(&path, &frames, &opts);
        assert_eq!(written, std::slice::from_ref(&path));
        assert_eq!(dir_entries(dir.path()), ["fire.mov"]);
        let info = probe(&path).unwrap();
        assert_eq!(
            (info.decoder, info.size, info.frame_count),
            (Decoder::Ffmpeg, size(33, 17), Some(6))
        );
        assert!((info.fps - 30000.0 / 1001.0).abs() < 1e-6, "{}", info.fps);
        let probe = std::process::Command::new("ffprobe")
            .args(["-v", "error", "-show_streams"])
            .arg(&path)
            .output()
            .unwrap();
        let streams = String::from_utf8_lossy(&probe.stdout);
        for want in [
            "codec_name=prores",
            "profile=4444",
            "color_transfer=iec61966-2-1",
            "color_primaries=bt709",
        ] {
            assert!(streams.contains(want), "{want} not in {streams}");
        }
        assert!(streams.contains("pix_fmt=yuva444p"), "{streams}");
        // ignis reads it back (through ffmpeg) with its alpha.
        let back: Vec<Vec<u8>> = read_all(&path)
            .iter()
            .map(|f| {
                f.data()
                    .iter()
                    .flat_map(|p| {
                        let s =
                            |v: f32| (ignis_core::palette::linear_to_srgb(v) * 255.0).round() as u8;
                        [s(p[0]), s(p[1]), s(p[2]), (p[3] * 255.0).round() as u8]
                    })
                    .collect()
            })
            .collect();
        assert_eq!(back.len(), 6);
        let (alpha, colour) = alpha_and_colour_error(&frames, &back);
        println!("mov: worst alpha error {alpha} levels, colour {colour:.2} levels");
        // ProRes 4444 keeps alpha to the 8-bit level and colour within a level (measured:
        // 1 level of alpha at worst, 0.16 mean in colour).
        assert!(alpha <= 1.0, "alpha off by {alpha} levels");
        assert!(colour < 1.0, "colour off by {colour:.2} levels");
    }

    #[test]
    fn webm_is_vp8_with_alpha() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..8).map(|t| test_frame(size(64, 48), t, true)).collect();
        let path = dir.path().join("fire.webm");
        write_all(&path, &frames, &WriteOptions::default());
        assert_eq!(dir_entries(dir.path()), ["fire.webm"]);
        let info = probe(&path).unwrap();
        assert_eq!((info.size, info.frame_count), (size(64, 48), Some(8)));
        // libvpx's decoder reads the alpha stream (ffmpeg's own VP8 decoder drops it).
        let back = ffmpeg_rgba(&path, Some("libvpx"), size(64, 48));
        assert_eq!(back.len(), 8);
        let (alpha, colour) = alpha_and_colour_error(&frames, &back);
        println!("webm: worst alpha error {alpha} levels, colour {colour:.2} levels");
        // Lossy 4:2:0 at constant quality 10, on an alpha pattern of 3×2-pixel blocks
        // with steps of up to 255: measured 4 levels of alpha at worst, 1.8 mean in colour.
        assert!(alpha <= 16.0, "alpha off by {alpha} levels");
        assert!(colour < 4.0, "colour off by {colour:.2} levels");
        let mean_alpha: f64 = back
            .iter()
            .flat_map(|b| b.chunks_exact(4).map(|p| p[3] as f64))
            .sum::<f64>()
            / (8.0 * 64.0 * 48.0);
        let want: f64 = frames
            .iter()
            .flat_map(|f| f.data().iter().map(|p| p[3] as f64 * 255.0))
            .sum::<f64>()
            / (8.0 * 64.0 * 48.0);
        assert!((mean_alpha - want).abs() < 2.0, "{mean_alpha} vs {want}");
        // Read back by Ignis: what libvpx decodes, alpha included (libvpx is chosen for a
        // stream tagged with alpha; ffmpeg's own VP8 decoder gave alpha 255 everywhere).
        assert!(info.codec.contains("with alpha"), "{}", info.codec);
        let ours = read_all(&path);
        assert_eq!(ours.len(), back.len());
        for (f, b) in ours.iter().zip(&back) {
            let theirs = bench_support::srgba8_to_linear(f.size(), b);
            assert!(mae_srgb8(f, &theirs) < 0.01, "colour differs from libvpx's");
            let alpha = f
                .data()
                .iter()
                .zip(theirs.data())
                .map(|(p, q)| (p[3] - q[3]).abs());
            assert!(
                alpha.fold(0.0f32, f32::max) < 1e-6,
                "alpha differs from libvpx's"
            );
        }
        // the same frames give the same bytes (the WebM muxer's UIDs are not drawn at
        // random), as every other writer's do
        let again = dir.path().join("again.webm");
        write_all(&again, &frames, &WriteOptions::default());
        assert!(
            std::fs::read(&again).unwrap() == std::fs::read(&path).unwrap(),
            "two WebM files of the same frames differ"
        );
    }

    #[test]
    fn a_failed_video_with_alpha_leaves_nothing() {
        if !have_ffmpeg() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fire.mov");
        // Dropped before finish: ffmpeg is stopped and its temporary removed.
        let mut w = create(&path, size(32, 16), &WriteOptions::default()).unwrap();
        w.push(&test_frame(size(32, 16), 0, true)).unwrap();
        drop(w);
        assert!(
            dir_entries(dir.path()).is_empty(),
            "{:?}",
            dir_entries(dir.path())
        );
        // A frame of the wrong size is refused and the output abandoned.
        let mut w = create(&path, size(32, 16), &WriteOptions::default()).unwrap();
        assert!(w.push(&test_frame(size(16, 16), 0, true)).is_err());
        drop(w);
        // Too large for ProRes: refused before ffmpeg starts.
        let big = create(&path, size(16_384, 8), &WriteOptions::default());
        assert!(
            matches!(big, Err(MediaError::LimitExceeded(_))),
            "{:?}",
            big.err()
        );
        assert!(
            dir_entries(dir.path()).is_empty(),
            "{:?}",
            dir_entries(dir.path())
        );
    }

    /// `ffprobe` reads the stream and `ffmpeg` decodes it without a single error message.
    fn ffprobe_checks(path: &Path, w: u32, h: u32, n: u32) {
        if !have_ffmpeg() {
            return;
        }
        let out = std::process::Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-select_streams",
                "v:0",
                "-count_frames",
                "-show_entries",
            ])
            .arg("stream=codec_name,profile,width,height,nb_frames,nb_read_frames")
            .args(["-of", "default=noprint_wrappers=1"])
            .arg(path)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && out.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for want in [
            "codec_name=h264".to_string(),
            format!("width={w}"),
            format!("height={h}"),
            format!("nb_read_frames={n}"),
        ] {
            assert!(text.contains(&want), "ffprobe output lacks {want}:\n{text}");
        }
        let dec = std::process::Command::new("ffmpeg")
            .args(["-v", "error", "-i"])
            .arg(path)
            .args(["-f", "null", "-"])
            .output()
            .unwrap();
        assert!(
            dec.status.success() && dec.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&dec.stderr)
        );
    }

    /// `n` test frames of 12×10 written as the 24-fps flipbook `dir/fire.png` with 2-px
    /// padding: the frames, the sheet's path and the files written.
    fn padded_flipbook(dir: &Path, n: u32) -> (Vec<RgbaFrame>, PathBuf, Vec<PathBuf>) {
        let frames: Vec<_> = (0..n).map(|t| test_frame(size(12, 10), t, true)).collect();
        let path = dir.join("fire.png");
        let opts = WriteOptions {
            fps: 24.0,
            flipbook: FlipbookOptions {
                padding: 2,
                ..Default::default()
            },
            ..Default::default()
        };
        let written = write_all(&path, &frames, &opts);
        (frames, path, written)
    }

    #[test]
    fn flipbook_sheet_and_json_roundtrip() {
        let dir = tempfile::tempdir().unwrap();
        let (frames, path, written) = padded_flipbook(dir.path(), 10);
        let json = dir.path().join("fire.json");
        assert_eq!(written, [path.clone(), json.clone()]);
        assert_eq!(dir_entries(dir.path()), ["fire.json", "fire.png"]);
        let fb = read_flipbook(&json).unwrap();
        let m = &fb.meta;
        assert_eq!(
            (m.image.as_str(), m.frame_width, m.frame_height),
            ("fire.png", 12, 10)
        );
        // 10 frames: 2 × 5 wastes no cell and gives the squarer sheet (32×70, not 80×28).
        assert_eq!((m.columns, m.rows, m.frame_count, m.padding), (2, 5, 10, 2));
        assert_eq!((m.fps, m.loop_, m.alpha), (24.0, true, AlphaMode::Straight));
        assert_eq!(m.order, "row-major, top-left first");
        // The sheet has exactly the size the JSON implies, and the padding bleeds edges.
        let sheet = read_image(&path).unwrap();
        assert_eq!(sheet.size(), size(2 * 16, 5 * 14));
        assert_eq!(sheet.get(16, 14), frames[3].get(0, 0)); // cell (1,1) corner = frame 3 (0,0)
        assert_eq!(sheet.get(16 + 2, 14 + 2), frames[3].get(0, 0));
        assert_eq!(sheet.get(16 + 15, 14 + 8), frames[3].get(11, 6));
        assert_eq!(fb.frames, frames);
        let text = std::fs::read_to_string(&json).unwrap();
        for key in [
            "\"frame_width\"",
            "\"columns\"",
            "\"rows\"",
            "\"frame_count\"",
            "\"loop\"",
            "\"padding\"",
            "\"alpha\": \"straight\"",
        ] {
            assert!(text.contains(key), "{key} missing from {text}");
        }
    }

    /// `trim`: the cells hold the box of every pixel any frame shows (alpha not 0 in 8
    /// bits) and one transparent pixel around it; the JSON says where that box lies; the
    /// cropped frames equal the untrimmed sheet's frames there. Nothing visible, or the
    /// whole frame visible: no trim.
    #[test]
    fn trimmed_flipbook_holds_the_visible_box() {
        let dir = tempfile::tempdir().unwrap();
        let sz = size(20, 16);
        // a block moving right over x 5..=10, y 4..=10, and a pixel too faint for 8 bits
        let frames: Vec<RgbaFrame> = (0..4)
            .map(|t| {
                let mut f = RgbaFrame::new(sz);
                for y in 4..11 {
                    for x in 5 + t..8 + t {
                        f.data_mut()[y * 20 + x] = [0.8, 0.4, 0.1, 0.5 + 0.1 * t as f32];
                    }
                }
                f.data_mut()[19] = [1.0, 1.0, 1.0, 0.001];
                f
            })
            .collect();
        let opts = |trim: bool| WriteOptions {
            flipbook: FlipbookOptions {
                trim,
                padding: 2,
                ..Default::default()
            },
            ..Default::default()
        };
        write_all(&dir.path().join("full.png"), &frames, &opts(false));
        write_all(&dir.path().join("trim.png"), &frames, &opts(true));
        let full = read_flipbook(&dir.path().join("full.json")).unwrap();
        let tr = read_flipbook(&dir.path().join("trim.json")).unwrap();
        assert_eq!(full.meta.trimmed, None);
        assert_eq!((tr.meta.frame_width, tr.meta.frame_height), (8, 9));
        assert_eq!(
            tr.meta.trimmed,
            Some(Trimmed {
                from_width: 20,
                from_height: 16,
                x: 4,
                y: 3
            })
        );
        assert_eq!((tr.meta.cell_width, tr.meta.padding), (8 + 4, 2));
        assert_eq!(tr.frames.len(), 4);
        for (a, b) in full.frames.iter().zip(&tr.frames) {
            for y in 0..9 {
                for x in 0..8 {
                    assert_eq!(a.get(x + 4, y + 3), b.get(x, y), "({x}, {y})");
                }
            }
            // nothing visible was cut off
            for y in 0..16 {
                for x in 0..20 {
                    let inside = (4..12).contains(&x) && (3..12).contains(&y);
                    assert!(inside || a.get(x, y)[3] == 0.0, "({x}, {y}) cut");
                }
            }
        }
        let clear = vec![RgbaFrame::new(sz); 2];
        assert_eq!(ignis_media::write::visible_box(&clear, sz), None);
        let whole = vec![RgbaFrame::filled(sz, [0.5, 0.5, 0.5, 1.0]); 2];
        assert_eq!(ignis_media::write::visible_box(&whole, sz), None);
        assert_eq!(
            ignis_media::write::visible_box(&frames, sz),
            Some((4, 3, 8, 9))
        );
        write_all(&dir.path().join("clear.png"), &clear, &opts(true));
        let c = read_flipbook(&dir.path().join("clear.json")).unwrap();
        assert_eq!((c.meta.frame_width, c.meta.trimmed), (20, None));
    }

    /// A flipbook reads as footage: its sheet (or its sidecar) gives its frames in order at
    /// its fps, and a range applies; its fingerprint covers both files. An image whose JSON
    /// names another sheet, or is not a sidecar, stays one still; a sidecar given as footage
    /// that is not one, or that does not fit its sheet, is refused by name.
    #[test]
    fn a_flipbook_reads_as_footage() {
        let dir = tempfile::tempdir().unwrap();
        let (frames, path, _) = padded_flipbook(dir.path(), 7);
        let json = dir.path().join("fire.json");
        for src in [&path, &json] {
            let info = probe(src).unwrap();
            assert_eq!(
                (info.decoder, info.size, info.fps, info.frame_count),
                (Decoder::Flipbook, size(12, 10), 24.0, Some(7))
            );
            assert!(info.codec.contains("flipbook"), "{}", info.codec);
            assert_eq!(read_all(src), frames);
            assert_eq!(source_files(src).unwrap(), [path.clone(), json.clone()]);
        }
        let range = ReadOptions {
            range: Some(FrameRange::frames(2, Some(5))),
            ..Default::default()
        };
        let part: Vec<_> = open(&path, &range).unwrap().map(|f| f.unwrap()).collect();
        assert_eq!(part, frames[2..5]);
        // the same sheet under another name, with a copy of the sidecar (naming fire.png)
        let other = dir.path().join("other.png");
        std::fs::copy(&path, &other).unwrap();
        std::fs::copy(&json, dir.path().join("other.json")).unwrap();
        let info = probe(&other).unwrap();
        assert_eq!((info.decoder, info.frame_count), (Decoder::Image, Some(1)));
        assert_eq!(source_files(&other).unwrap(), std::slice::from_ref(&other));
        // a JSON beside an image that is not a sidecar
        let plain = dir.path().join("plain.png");
        std::fs::copy(&path, &plain).unwrap();
        std::fs::write(dir.path().join("plain.json"), "{\"image\": 3}").unwrap();
        assert_eq!(probe(&plain).unwrap().decoder, Decoder::Image);
        let e = probe(&dir.path().join("plain.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not an Ignis flipbook sidecar"), "{e}");
        // a sidecar whose grid does not fit its sheet
        let text = std::fs::read_to_string(&json).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let mut v2 = v.clone();
        v2["columns"] = 40.into();
        std::fs::write(&json, v2.to_string()).unwrap();
        let e = probe(&path).unwrap_err().to_string();
        assert!(e.contains("do not fit"), "{e}");
        v2 = v.clone();
        v2["fps"] = 0.into();
        std::fs::write(&json, v2.to_string()).unwrap();
        let e = probe(&json).unwrap_err().to_string();
        assert!(e.contains("fps"), "{e}");
    }

    #[test]
    fn flipbook_premultiplied() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..3).map(|t| test_frame(size(5, 5), t, true)).collect();
        let path = dir.path().join("pm.png");
        let opts = WriteOptions {
            flipbook: FlipbookOptions {
                alpha: AlphaMode::Premultiplied,
                columns: Some(3),
                ..Default::default()
            },
            ..Default::default()
        };
        write_all(&path, &frames, &opts);
        let fb = read_flipbook(&dir.path().join("pm.json")).unwrap();
        assert_eq!(
            (fb.meta.columns, fb.meta.rows, fb.meta.alpha),
            (3, 1, AlphaMode::Premultiplied)
        );
        for (a, b) in frames.iter().zip(&fb.frames) {
            for (p, q) in a.data().iter().zip(b.data()) {
                if p[3] >= 0.25 {
                    for c in 0..3 {
                        assert!((p[c] - q[c]).abs() < 0.03, "{p:?} vs {q:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn jpeg_sequence_and_tiff_still() {
        let dir = tempfile::tempdir().unwrap();
        let seq = dir.path().join("jpg");
        std::fs::create_dir(&seq).unwrap();
        let img = image::RgbImage::from_fn(20, 10, |x, y| {
            image::Rgb([(x * 12) as u8, (y * 25) as u8, 128])
        });
        for i in 0..3 {
            img.save(seq.join(format!("frame{i}.jpg"))).unwrap();
        }
        let info = probe(&seq).unwrap();
        assert_eq!(
            (info.codec.as_str(), info.frame_count, info.size),
            ("jpg sequence", Some(3), size(20, 10))
        );
        let frames = read_all(&seq);
        assert_eq!(frames.len(), 3);
        let p = frames[0].get(10, 5);
        assert!(
            (p[0] - srgb_to_linear(120.0 / 255.0)).abs() < 0.03 && p[3] == 1.0,
            "{p:?}"
        );
        let tif = dir.path().join("still.tif");
        img.save(&tif).unwrap();
        let f = read_image(&tif).unwrap();
        assert_eq!(f.get(3, 4)[0], srgb_to_linear(36.0 / 255.0));
        assert_eq!(probe(&tif).unwrap().decoder, Decoder::Image);
    }

    #[test]
    fn still_png_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let f = test_frame(size(7, 5), 1, true);
        let path = dir.path().join("still.png");
        write_png(&path, &f).unwrap();
        assert_eq!(read_image(&path).unwrap(), f);
        let info = probe(&path).unwrap();
        assert_eq!((info.decoder, info.frame_count), (Decoder::Image, Some(1)));
        assert_eq!(dir_entries(dir.path()), ["still.png"]);
    }
}

mod bad_input {
    use super::*;

    #[test]
    fn missing_file() {
        let e = probe(Path::new("/nonexistent/ignis/fire.mp4")).unwrap_err();
        assert!(
            matches!(&e, MediaError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound),
            "{e}"
        );
        assert!(e.to_string().contains("/nonexistent/ignis/fire.mp4"));
        assert!(open(
            Path::new("/nonexistent/ignis/%04d.png"),
            &ReadOptions::default()
        )
        .is_err());
    }

    #[test]
    fn zero_byte_files() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["empty.mp4", "empty.png", "empty.gif"] {
            let p = dir.path().join(name);
            std::fs::write(&p, b"").unwrap();
            let e = open(&p, &ReadOptions::default()).err().unwrap();
            assert!(matches!(e, MediaError::Decode { .. }), "{e}");
            assert!(e.to_string().contains("empty"), "{e}");
            assert!(read_image(&p).is_err());
        }
    }

    /// Ignis's own non-footage outputs given as footage say what they are and which command
    /// takes them (the layouts `ignis eigen train` and `ignis learned train` write; those
    /// crates test the real files' commands).
    #[test]
    fn a_database_or_a_model_given_as_footage_says_what_it_is() {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("fire.db");
        std::fs::create_dir_all(db.join("packs")).unwrap();
        std::fs::write(db.join("manifest.json"), "{}").unwrap();
        let e = probe(&db).unwrap_err().to_string();
        assert!(
            e.contains("an Eigenfire database") && e.contains("ignis eigen info"),
            "{e}"
        );
        // a directory with a manifest alone is just a directory without frames
        std::fs::remove_dir(db.join("packs")).unwrap();
        let e = probe(&db).unwrap_err().to_string();
        assert!(e.contains("holds no PNG"), "{e}");
        let model = dir.path().join("candle.flame");
        std::fs::write(&model, "IGNIS-LEARNED-FLAME 1 sha256:00\n{}").unwrap();
        for e in [
            probe(&model).unwrap_err(),
            open(&model, &ReadOptions::default()).err().unwrap(),
        ] {
            let e = e.to_string();
            assert!(
                e.contains("a learned-flame model") && e.contains("ignis learned synth"),
                "{e}"
            );
        }
        // text files: a fire file, a scenario, a clips file, any other text
        for (text, says) in [
            (
                "seed = 1\n[[fire]]\ncurve = {}\n",
                "a fire file, not footage; render it with `ignis volume render",
            ),
            (
                "database = \"x.db\"\nsequence = [\"a\"]\n[motions.a]\n",
                "an Eigenfire scenario, not footage; render it with `ignis eigen animate",
            ),
            (
                "[[clip]]\nname = \"c\"\n",
                "a clips file, not footage; train a database from it with `ignis eigen train",
            ),
            (
                "just some notes\n\twith a tab, ünïcödé\r\n",
                "a text file, not footage (footage is",
            ),
        ] {
            let p = dir.path().join("file.toml");
            std::fs::write(&p, text).unwrap();
            let e = probe(&p).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
        // the text formats ffmpeg reads as video are left to it
        let list = dir.path().join("list.ffconcat");
        std::fs::write(&list, "ffconcat version 1.0\nfile 'nothing.mp4'\n").unwrap();
        if let Err(e) = probe(&list) {
            assert!(!e.to_string().contains("text file"), "{e}");
        }
        // text-like first bytes over binary data (a YUV4MPEG2 header, then 8-bit samples):
        // not called text
        let y4m = dir.path().join("clip.y4m");
        let mut bytes = b"YUV4MPEG2 W2 H2 F30:1 Ip A1:1 C444\nFRAME\n".to_vec();
        bytes.extend([16u8, 16, 16, 16, 1, 2, 3, 4, 5, 6, 7, 8]);
        std::fs::write(&y4m, bytes).unwrap();
        if let Err(e) = probe(&y4m) {
            assert!(!e.to_string().contains("text file"), "{e}");
        }
    }

    #[test]
    fn garbage_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("noise.mp4");
        std::fs::write(
            &p,
            (0..5000u32)
                .map(|i| (i * 7919 % 251) as u8)
                .collect::<Vec<_>>(),
        )
        .unwrap();
        assert!(open(&p, &ReadOptions::default()).is_err());
    }

    #[test]
    fn truncated_mp4() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..10)
            .map(|t| test_frame(Size::new(32, 32).unwrap(), t, false))
            .collect();
        let path = dir.path().join("whole.mp4");
        write_all(&path, &frames, &WriteOptions::default());
        let bytes = std::fs::read(&path).unwrap();
        for cut in [8, 40, bytes.len() / 2, bytes.len() - 20] {
            let t = dir.path().join(format!("cut{cut}.mp4"));
            std::fs::write(&t, &bytes[..cut]).unwrap();
            let result =
                open(&t, &ReadOptions::default()).and_then(|r| r.collect::<Result<Vec<_>, _>>());
            let e = result.expect_err("a truncated MP4 must not decode cleanly");
            assert!(matches!(e, MediaError::Decode { .. }), "{e}");
        }
    }

    #[test]
    fn truncated_footage_errors_without_panicking() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let t = dir.path().join("candle-cut.mp4");
        std::fs::write(&t, &bytes[..bytes.len() / 3]).unwrap();
        let result =
            open(&t, &ReadOptions::default()).and_then(|r| r.collect::<Result<Vec<_>, _>>());
        assert!(result.is_err());
    }

    #[test]
    fn mixed_frame_sizes_name_the_offender() {
        let dir = tempfile::tempdir().unwrap();
        let s = |w, h| Size::new(w, h).unwrap();
        write_png(&dir.path().join("f01.png"), &RgbaFrame::new(s(8, 8))).unwrap();
        write_png(&dir.path().join("f02.png"), &RgbaFrame::new(s(8, 8))).unwrap();
        write_png(&dir.path().join("f03.png"), &RgbaFrame::new(s(9, 8))).unwrap();
        write_png(&dir.path().join("f04.png"), &RgbaFrame::new(s(7, 8))).unwrap();
        let e = open(dir.path(), &ReadOptions::default()).err().unwrap();
        match &e {
            MediaError::Decode { path, .. } => assert!(path.ends_with("f03.png"), "{e}"),
            other => panic!("expected a decode error, got {other}"),
        }
        assert!(
            e.to_string().contains("f03.png") && e.to_string().contains("9x8"),
            "{e}"
        );
    }

    #[test]
    fn empty_frame_in_sequence_is_named() {
        let dir = tempfile::tempdir().unwrap();
        write_png(
            &dir.path().join("a0.png"),
            &RgbaFrame::new(Size::new(4, 4).unwrap()),
        )
        .unwrap();
        std::fs::write(dir.path().join("a1.png"), b"").unwrap();
        let e = open(dir.path(), &ReadOptions::default()).err().unwrap();
        assert!(
            e.to_string().contains("a1.png") && e.to_string().contains("empty"),
            "{e}"
        );
    }

    #[test]
    fn sequence_range_errors() {
        let dir = tempfile::tempdir().unwrap();
        for i in 0..3 {
            write_png(
                &dir.path().join(format!("{i}.png")),
                &RgbaFrame::new(Size::new(4, 4).unwrap()),
            )
            .unwrap();
        }
        let r = |a, b| ReadOptions {
            range: Some(FrameRange::frames(a, b)),
            ..Default::default()
        };
        assert!(open(dir.path(), &r(2, Some(1))).is_err());
        assert!(open(dir.path(), &r(3, None)).is_err());
        assert!(open(dir.path(), &r(1, Some(4))).is_err());
        assert_eq!(open(dir.path(), &r(1, Some(3))).unwrap().count(), 2);
    }

    /// Every format: a writer dropped half-way, or one with no frames, leaves nothing.
    #[test]
    fn failed_writes_leave_nothing() {
        let size = Size::new(16, 12).unwrap();
        let frame = test_frame(size, 0, true);
        for name in [
            "a.mp4",
            "a.gif",
            "a.png",
            "seq/",
            "pat/%04d.png",
            "exr/%04d.exr",
        ] {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join(name);
            // Dropped without finish.
            let mut w = create(&path, size, &WriteOptions::default()).unwrap();
            w.push(&frame).unwrap();
            w.push(&frame).unwrap();
            // A wrong-size frame is refused without writing.
            assert!(w.push(&RgbaFrame::new(Size::new(3, 3).unwrap())).is_err());
            drop(w);
            assert!(
                dir_entries(dir.path()).is_empty(),
                "{name}: left {:?}",
                dir_entries(dir.path())
            );
            // Finished with no frames.
            let w = create(&path, size, &WriteOptions::default()).unwrap();
            assert!(w.finish().is_err());
            assert!(
                dir_entries(dir.path()).is_empty(),
                "{name}: left {:?}",
                dir_entries(dir.path())
            );
        }
        // A sequence into an existing directory leaves that directory as it was.
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("out")).unwrap();
        let mut w = create(&dir.path().join("out"), size, &WriteOptions::default()).unwrap();
        w.push(&frame).unwrap();
        drop(w);
        assert!(dir_entries(&dir.path().join("out")).is_empty());
    }

    #[test]
    fn bad_write_parameters() {
        let dir = tempfile::tempdir().unwrap();
        let size = Size::new(4, 4).unwrap();
        let e = create(&dir.path().join("x.mkv"), size, &WriteOptions::default())
            .err()
            .unwrap();
        assert!(
            matches!(e, MediaError::BadParameter { name: "path", .. }),
            "{e}"
        );
        let e = create(
            &dir.path().join("x.gif"),
            size,
            &WriteOptions {
                fps: 0.0,
                ..Default::default()
            },
        )
        .err()
        .unwrap();
        assert!(
            matches!(e, MediaError::BadParameter { name: "fps", .. }),
            "{e}"
        );
        let opts = WriteOptions {
            flipbook: FlipbookOptions {
                columns: Some(1),
                rows: Some(1),
                ..Default::default()
            },
            ..Default::default()
        };
        let mut w = create(&dir.path().join("fb.png"), size, &opts).unwrap();
        w.push(&RgbaFrame::new(size)).unwrap();
        w.push(&RgbaFrame::new(size)).unwrap();
        assert!(w.finish().is_err());
        assert!(dir_entries(dir.path()).is_empty());
    }
}

/// Issue 18 regressions (defects 5, 6, 8, 9, 13, 14).
mod hardening {
    use super::*;

    fn size() -> Size {
        Size::new(8, 6).unwrap()
    }

    /// The writer measures seam and ghost as frames stream past (it keeps 16 bytes a
    /// frame, not the metric frames): the same values, bit for bit, as measuring the
    /// metric frames of everything pushed; none before there are enough frames.
    #[test]
    fn streamed_loop_quality_equals_the_measure_of_all_frames() {
        use ignis_core::loopq;
        let dir = tempfile::tempdir().unwrap();
        let opts = WriteOptions {
            background: [0.1, 0.0, 0.2],
            ..Default::default()
        };
        let s = Size::new(40, 30).unwrap();
        // a jump (frame 9 repeats frame 2) and a soft frame (a blend of two neighbours)
        let mut frames: Vec<RgbaFrame> = (0..24).map(|t| test_frame(s, t, true)).collect();
        frames[9] = frames[2].clone();
        let (a, b) = (frames[14].clone(), frames[16].clone());
        for y in 0..30 {
            for x in 0..40 {
                let (p, q) = (a.get(x, y), b.get(x, y));
                frames[15].set(x, y, std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
            }
        }
        let mut w = create(&dir.path().join("q.mp4"), s, &opts).unwrap();
        let mut metric = Vec::new();
        for (i, f) in frames.iter().enumerate() {
            w.push(f).unwrap();
            metric.push(loopq::metric_frame_rgba(f, opts.background));
            let loop_q = loopq::loop_quality(&metric).ok();
            let seq_q = loopq::sequence_quality(&metric).ok();
            assert_eq!(w.loop_quality(), loop_q, "after {} frames", i + 1);
            assert_eq!(w.sequence_quality(), seq_q, "after {} frames", i + 1);
            assert_eq!((loop_q.is_some(), seq_q.is_some()), (i >= 1, i >= 2));
        }
        // the largest step is into or out of the repeated frame
        assert!(matches!(w.loop_quality().unwrap().seam_at, 8 | 9));
        w.finish().unwrap();
    }

    /// A grid of no columns or no rows is refused when the flipbook is created, before any
    /// frame is rendered or decoded for it (not when it is finished).
    #[test]
    fn an_empty_grid_is_refused_at_creation() {
        let dir = tempfile::tempdir().unwrap();
        for (columns, rows) in [(Some(0), None), (None, Some(0)), (Some(3), Some(0))] {
            let mut opts = WriteOptions::default();
            opts.flipbook.columns = columns;
            opts.flipbook.rows = rows;
            let e = create(&dir.path().join("g.png"), size(), &opts)
                .err()
                .expect("refused")
                .to_string();
            assert!(e.contains("columns and rows must be ≥ 1"), "{e}");
        }
        assert_eq!(dir_entries(dir.path()), Vec::<String>::new());
    }

    /// Defect 9: frame rates outside 0.001..=1000 are refused for every format.
    #[test]
    fn fps_out_of_range_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        for fps in [1e30, 1e-30, f64::NAN, -1.0, 1000.5] {
            for name in ["q.mp4", "q.gif", "q.png", "seq/"] {
                let opts = WriteOptions {
                    fps,
                    ..Default::default()
                };
                let e = create(&dir.path().join(name), size(), &opts).err().unwrap();
                assert!(
                    matches!(e, MediaError::BadParameter { name: "fps", .. }),
                    "{fps} {name}: {e}"
                );
            }
        }
        assert!(dir_entries(dir.path()).is_empty());
    }

    /// Defect 13: a device node (or FIFO) as output is refused, not replaced.
    #[cfg(unix)]
    #[test]
    fn device_nodes_are_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        for fmt in [Format::Mp4, Format::Gif, Format::Flipbook] {
            let opts = WriteOptions {
                format: Some(fmt),
                ..Default::default()
            };
            let e = create(Path::new("/dev/null"), size(), &opts).err().unwrap();
            assert!(e.to_string().contains("a device"), "{e}");
        }
        assert!(std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.mp4");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid path string.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        let e = create(&fifo, size(), &WriteOptions::default())
            .err()
            .unwrap();
        assert!(e.to_string().contains("a FIFO"), "{e}");
        assert!(ignis_media::write_png(&fifo, &RgbaFrame::new(size())).is_err());
    }

    /// Defect 5: a huge printf width is an error, not a formatting panic.
    #[test]
    fn huge_pattern_width_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        for pat in [
            "out/%65536d.png",
            "out/%99999999999999999999999d.png",
            "out/%21d.exr",
        ] {
            let e = create(&dir.path().join(pat), size(), &WriteOptions::default())
                .err()
                .unwrap();
            assert!(e.to_string().contains("at most 20"), "{pat}: {e}");
        }
        let e = probe(&dir.path().join("%65536d.png")).err().unwrap();
        assert!(e.to_string().contains("pattern"), "{e}");
    }

    /// Defect 8: EXR sequences are the same bytes every run, whatever the thread count,
    /// with scan lines in increasing Y.
    #[test]
    fn exr_bytes_are_deterministic() {
        let frames: Vec<_> = (0..2)
            .map(|t| test_frame(Size::new(70, 40).unwrap(), t, true))
            .collect();
        let write = |threads: usize| {
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("e/%02d.exr");
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| write_all(&p, &frames, &WriteOptions::default()));
            let b = std::fs::read(dir.path().join("e/01.exr")).unwrap();
            assert_eq!(read_all(&p).len(), 2);
            b
        };
        let a = write(1);
        assert_eq!(a, write(2));
        assert_eq!(a, write(1));
        // lineOrder attribute: type "lineOrder", size 1, value 0 = INCREASING_Y.
        let key = b"lineOrder\0lineOrder\0\x01\0\0\0";
        let at = a
            .windows(key.len())
            .position(|w| w == key)
            .expect("lineOrder attribute");
        assert_eq!(a[at + key.len()], 0);
    }

    /// Defects 6 and 14: a sequence written into an existing directory replaces it in one
    /// step (old files with other names kept), and nothing hidden is left beside it;
    /// stale temporaries of a dead writer are removed by the next run.
    #[test]
    fn sequence_into_existing_directory_is_swapped_in() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out/");
        let f0: Vec<_> = (0..3).map(|t| test_frame(size(), t, true)).collect();
        write_all(&out, &f0, &WriteOptions::default());
        std::fs::write(out.join("notes.txt"), "keep").unwrap();
        // A dead writer's leftovers, in the parent and in the directory.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = dir.path().join(format!(".out.ignis-tmp-{dead}.abc.dir"));
        std::fs::create_dir(&stale).unwrap();
        std::fs::write(stale.join("0000.png"), "x").unwrap();
        let f1: Vec<_> = (5..7).map(|t| test_frame(size(), t, true)).collect();
        write_all(&out, &f1, &WriteOptions::default());
        assert_eq!(dir_entries(dir.path()), ["out"]);
        assert_eq!(
            dir_entries(&out),
            ["0000.png", "0001.png", "0002.png", "notes.txt"]
        );
        let back = read_all(&out.join("%04d.png"));
        assert_eq!(&back[..2], &f1[..]);
        assert_eq!(back[2], f0[2]);
        assert_eq!(
            std::fs::read_to_string(out.join("notes.txt")).unwrap(),
            "keep"
        );
        // Flipbook: exactly the PNG and the JSON, from one commit.
        let fb = dir.path().join("fb.png");
        write_all(&fb, &f1, &WriteOptions::default());
        write_all(&fb, &f0, &WriteOptions::default());
        assert_eq!(dir_entries(dir.path()), ["fb.json", "fb.png", "out"]);
        assert_eq!(
            read_flipbook(&dir.path().join("fb.json")).unwrap().frames,
            f0
        );
    }
}
/// Engine presets read back by decoders written from each engine's documented convention
/// (tile counts from the engine's own JSON keys, the engine's UV origin, its green
/// direction), not from `read_flipbook`.
mod engines {
    use super::*;
    use ignis_media::write::motion::MV_NEUTRAL;
    use serde_json::Value;

    const W: u32 = 24;
    const H: u32 = 20;
    const STEP: [f32; 2] = [4.0, 2.0];
    const FRAMES: u32 = 5;

    fn centre(k: u32) -> [f32; 2] {
        [5.5 + STEP[0] * k as f32, 5.5 + STEP[1] * k as f32]
    }

    /// Frame `k`: a disc of radius 3 (linear colour (1, 0.5, 0.2), alpha 0.5) centred at
    /// `centre(k)` on transparent black.
    fn disc(k: u32) -> RgbaFrame {
        let mut f = RgbaFrame::new(Size::new(W, H).unwrap());
        let [cx, cy] = centre(k);
        for y in 0..H {
            for x in 0..W {
                let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
                if d <= 3.0 {
                    f.set(x, y, [1.0, 0.5, 0.2, 0.5]);
                }
            }
        }
        f
    }

    /// A flow for these discs: the shift of the disc's centroid from `a` to `b` where
    /// `a`'s disc is, zero elsewhere (what a dense flow of them gives). Tests with
    /// `ignis_flow` itself live in the CLI's tests.
    fn disc_flow() -> MotionSource {
        fn centroid(f: &RgbaFrame) -> [f32; 2] {
            let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
            for y in 0..f.height() {
                for x in 0..f.width() {
                    let a = f.get(x, y)[3];
                    sx += a * x as f32;
                    sy += a * y as f32;
                    n += a;
                }
            }
            [sx / n, sy / n]
        }
        MotionSource::new(|a: &RgbaFrame, b: &RgbaFrame| {
            let (ca, cb) = (centroid(a), centroid(b));
            let d = [cb[0] - ca[0], cb[1] - ca[1]];
            Ok(a.data()
                .iter()
                .map(|p| if p[3] > 0.0 { d } else { [0.0, 0.0] })
                .collect())
        })
    }

    struct Sheet {
        meta: Value,
        colour: image::RgbaImage,
        mv: image::ImageBuffer<image::Rgb<u16>, Vec<u16>>,
    }

    fn write(dir: &Path, engine: Engine) -> Sheet {
        let path = dir.join(format!("{}.png", engine.name()));
        let opts = WriteOptions {
            loop_: false,
            flipbook: FlipbookOptions {
                engine,
                columns: Some(4), // 4 × 2 cells: cells 5..7 stay empty
                alpha: engine.conventions().alpha,
                motion: Some(disc_flow()),
                ..Default::default()
            },
            ..Default::default()
        };
        let frames: Vec<_> = (0..FRAMES).map(disc).collect();
        write_all(&path, &frames, &opts);
        let meta: Value =
            serde_json::from_slice(&std::fs::read(path.with_extension("json")).unwrap()).unwrap();
        let mv_name = meta["motion_vectors"]["image"].as_str().unwrap();
        Sheet {
            colour: image::open(&path).unwrap().into_rgba8(),
            mv: image::open(dir.join(mv_name)).unwrap().into_rgb16(),
            meta,
        }
    }

    /// What one engine's decoder needs: tiles across/down from the engine's keys, whether
    /// its UV origin is bottom-left, and whether its motion `v` points up.
    struct Convention {
        tiles: (u32, u32),
        v_up: bool,
    }

    fn convention(engine: Engine, m: &Value) -> Convention {
        let s = &m["engine_settings"];
        let n = |v: &Value| v.as_u64().unwrap() as u32;
        match engine {
            // Unity: Texture Sheet Animation Tiles X/Y; UV origin bottom-left.
            Engine::Unity => Convention {
                tiles: (
                    n(&s["Texture Sheet Animation"]["Tiles"]["X"]),
                    n(&s["Texture Sheet Animation"]["Tiles"]["Y"]),
                ),
                v_up: true,
            },
            // Unreal: SubImages_Horizontal/Vertical, sub-image 0 top-left, UV origin top-left.
            Engine::Unreal => Convention {
                tiles: (n(&s["SubImages_Horizontal"]), n(&s["SubImages_Vertical"])),
                v_up: false,
            },
            // Godot: particles_anim_h_frames / v_frames, UV origin top-left.
            Engine::Godot => Convention {
                tiles: (
                    n(&s["particles_anim_h_frames"]),
                    n(&s["particles_anim_v_frames"]),
                ),
                v_up: false,
            },
            // SideFX Labs: Columns / Rows, Houdini UVs (bottom-left), green flipped.
            Engine::Sidefx => Convention {
                tiles: (n(&s["Columns"]), n(&s["Rows"])),
                v_up: true,
            },
            Engine::Generic => Convention {
                tiles: (n(&s["columns"]), n(&s["rows"])),
                v_up: false,
            },
        }
    }

    /// The image pixel an engine samples for sub-image `k` at tile-UV `(tu, tv)` (in the
    /// engine's own UV orientation).
    fn engine_pixel(c: &Convention, sheet: (u32, u32), k: u32, tu: f32, tv: f32) -> (u32, u32) {
        let (tx, ty) = c.tiles;
        let (col, row_from_top) = (k % tx, k / tx);
        let u = (col as f32 + tu) / tx as f32;
        let (v, y_img) = if c.v_up {
            // Rows counted from the bottom in UV space; image rows from the top.
            let v = ((ty - 1 - row_from_top) as f32 + tv) / ty as f32;
            (v, (1.0 - v) * sheet.1 as f32)
        } else {
            let v = (row_from_top as f32 + tv) / ty as f32;
            (v, v * sheet.1 as f32)
        };
        let _ = v;
        (
            ((u * sheet.0 as f32).floor() as u32).min(sheet.0 - 1),
            (y_img.floor() as u32).min(sheet.1 - 1),
        )
    }

    /// Tile UV of frame pixel `(x, y)` (its centre) in the engine's orientation.
    fn tile_uv(m: &Value, c: &Convention, x: f32, y: f32) -> (f32, f32) {
        let n = |k: &str| m[k].as_u64().unwrap() as f32;
        let (cw, ch) = (n("cell_width"), n("cell_height"));
        let (fx, fy) = (n("frame_x"), n("frame_y"));
        let tu = (fx + x) / cw;
        let tv_down = (fy + y) / ch;
        (tu, if c.v_up { 1.0 - tv_down } else { tv_down })
    }

    #[test]
    fn every_preset_decodes_frame_and_motion() {
        let dir = tempfile::tempdir().unwrap();
        for engine in Engine::ALL {
            let s = write(dir.path(), engine);
            let c = convention(engine, &s.meta);
            assert_eq!(c.tiles, (4, 2), "{engine:?}");
            let dims = s.colour.dimensions();
            let scale = s.meta["motion_vectors"]["scale"].as_f64().unwrap() as f32;
            let (cw, ch) = (
                s.meta["cell_width"].as_f64().unwrap() as f32,
                s.meta["cell_height"].as_f64().unwrap() as f32,
            );
            for k in 0..FRAMES {
                // Frame k's disc centre is opaque-ish in sub-image k; the neighbours' centres
                // are empty there (a wrong cell or a flipped Y would read them).
                let at = |kk: u32| {
                    let [x, y] = centre(kk);
                    let (tu, tv) = tile_uv(&s.meta, &c, x, y);
                    engine_pixel(&c, dims, k, tu, tv)
                };
                let (px, py) = at(k);
                assert_eq!(s.colour.get_pixel(px, py)[3], 128, "{engine:?} frame {k}");
                for other in [k.wrapping_sub(1), k + 1] {
                    if other < FRAMES {
                        let (qx, qy) = at(other);
                        assert_eq!(s.colour.get_pixel(qx, qy)[3], 0, "{engine:?} frame {k}");
                    }
                }
                // Motion at the disc centre: (r*2-1)*scale in tile UV → pixels, the
                // engine's v direction turned into image rows.
                let p = s.mv.get_pixel(px, py);
                let f = |v: u16| (v as f32 / 65535.0) * 2.0 - 1.0;
                let du = f(p[0]) * scale * cw;
                let dv = f(p[1]) * scale * ch;
                let dy = if c.v_up { -dv } else { dv };
                assert!(
                    (du - STEP[0]).abs() < 0.5 && (dy - STEP[1]).abs() < 0.5,
                    "{engine:?} frame {k}: ({du}, {dy})"
                );
                // No motion away from the disc (the frame's far corner).
                let (tu, tv) = tile_uv(&s.meta, &c, W as f32 - 0.5, 0.5);
                let (qx, qy) = engine_pixel(&c, dims, k, tu, tv);
                let q = s.mv.get_pixel(qx, qy);
                assert_eq!((q[0], q[1]), (MV_NEUTRAL, MV_NEUTRAL), "{engine:?}");
            }
            // Empty cells: exactly zero motion (32768 = 128 in 8 bits) and transparent.
            for k in FRAMES..8 {
                for (tu, tv) in [(0.01, 0.01), (0.5, 0.5), (0.99, 0.99)] {
                    let (px, py) = engine_pixel(&c, dims, k, tu, tv);
                    let q = s.mv.get_pixel(px, py);
                    assert_eq!((q[0], q[1], q[2]), (MV_NEUTRAL, MV_NEUTRAL, 0));
                    assert_eq!(s.colour.get_pixel(px, py).0, [0, 0, 0, 0]);
                }
            }
        }
    }

    #[test]
    fn padding_alpha_and_colour_spaces_as_declared() {
        use ignis_core::palette::linear_to_srgb;
        let dir = tempfile::tempdir().unwrap();
        for engine in Engine::ALL {
            let s = write(dir.path(), engine);
            let m = &s.meta;
            let n = |k: &str| m[k].as_u64().unwrap() as u32;
            let (cw, ch, fx, fy) = (
                n("cell_width"),
                n("cell_height"),
                n("frame_x"),
                n("frame_y"),
            );
            assert_eq!(fx, engine.conventions().min_padding, "{engine:?}");
            // Extruded: every padding pixel repeats the nearest frame pixel (colour and
            // motion), in every cell.
            for k in 0..8u32 {
                let (ox, oy) = ((k % 4) * cw, (k / 4) * ch);
                for cy in 0..ch {
                    for cx in 0..cw {
                        let sx = cx.saturating_sub(fx).min(W - 1) + fx;
                        let sy = cy.saturating_sub(fy).min(H - 1) + fy;
                        assert_eq!(
                            s.colour.get_pixel(ox + cx, oy + cy),
                            s.colour.get_pixel(ox + sx, oy + sy)
                        );
                        assert_eq!(
                            s.mv.get_pixel(ox + cx, oy + cy),
                            s.mv.get_pixel(ox + sx, oy + sy)
                        );
                    }
                }
            }
            // Alpha as the JSON says, colour sRGB-encoded as declared.
            assert_eq!(m["color_space"], "srgb");
            assert_eq!(m["motion_vectors"]["color_space"], "linear");
            let [x, y] = centre(0);
            let p = s.colour.get_pixel(fx + x as u32, fy + y as u32).0;
            let premul = m["alpha"] == "premultiplied";
            assert_eq!(premul, engine == Engine::Godot);
            let a = if premul { 0.5 } else { 1.0 };
            let code = |v: f32| (linear_to_srgb(v * a) * 255.0).round() as u8;
            assert_eq!(p, [code(1.0), code(0.5), code(0.2), 128], "{engine:?}");
            if engine == Engine::Godot {
                assert_eq!(m["engine_settings"]["blend_mode"], "premul_alpha");
            }
        }
    }

    #[test]
    fn heat_hdr_variants_and_retime() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.png");
        let frames: Vec<_> = (0..6).map(|k| disc(k % 3)).collect();
        let opts = WriteOptions {
            flipbook: FlipbookOptions {
                variants: 2,
                heat: true,
                hdr: true,
                motion: Some(disc_flow()),
                ..Default::default()
            },
            ..Default::default()
        };
        let files = write_all(&path, &frames, &opts);
        let names: Vec<String> = files
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            ["v.png", "v.mv.png", "v.heat.png", "v.exr", "v.json"]
        );
        let fb = read_flipbook(&dir.path().join("v.json")).unwrap();
        assert_eq!((fb.meta.columns, fb.meta.rows, fb.meta.variants), (3, 2, 2));
        // Each row loops on its own: the last frame of a row moves back to its first
        // (−2 steps) after arriving from the one before (+1 step); its velocity is the
        // mean, −½ step.
        let mv = fb.motion.unwrap();
        let [x, y] = centre(2);
        let i = (y as usize) * W as usize + x as usize;
        let back = [-0.5 * STEP[0], -0.5 * STEP[1]];
        assert!(
            (mv[2][i][0] - back[0]).abs() < 0.01 && (mv[2][i][1] - back[1]).abs() < 0.01,
            "{:?}",
            mv[2][i]
        );
        let [x, y] = centre(0);
        // Heat: linear luminance of the premultiplied colour, scaled by the JSON's scale.
        let heat = image::open(dir.path().join("v.heat.png"))
            .unwrap()
            .into_luma16();
        let scale = fb.meta.heat.as_ref().unwrap().scale;
        let lum = (0.2126 + 0.7152 * 0.5 + 0.0722 * 0.2) * 0.5;
        assert!((scale - lum).abs() < 1e-6);
        assert_eq!(heat.get_pixel(x as u32, y as u32)[0], 65535);
        // HDR: linear premultiplied f32.
        let exr = image::open(dir.path().join("v.exr"))
            .unwrap()
            .into_rgba32f();
        let p = exr.get_pixel(x as u32, y as u32).0;
        assert!(
            (p[0] - 0.5).abs() < 1e-6 && (p[3] - 0.5).abs() < 1e-6,
            "{p:?}"
        );

        // Retime: 7 frames fill a 4 × 2 grid → 8 frames at 8/7 the fps.
        let path = dir.path().join("r.png");
        let frames: Vec<_> = (0..7).map(|k| disc(k % 5)).collect();
        let opts = WriteOptions {
            fps: 28.0,
            flipbook: FlipbookOptions {
                pot: true,
                fit_frames: true,
                ..Default::default()
            },
            ..Default::default()
        };
        write_all(&path, &frames, &opts);
        let fb = read_flipbook(&dir.path().join("r.json")).unwrap();
        assert_eq!(fb.meta.frame_count, 8);
        assert_eq!(fb.meta.fps, 32.0);
        assert_eq!(fb.meta.retimed.as_ref().unwrap().from_frames, 7);
    }

    #[test]
    fn bad_export_options_write_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let size = Size::new(W, H).unwrap();
        let try_write = |name: &str, n: u32, fb: FlipbookOptions| {
            let opts = WriteOptions {
                flipbook: fb,
                ..Default::default()
            };
            let path = dir.path().join(name);
            let mut w = match create(&path, size, &opts) {
                Ok(w) => w,
                Err(e) => return e,
            };
            for k in 0..n {
                w.push(&disc(k)).unwrap();
            }
            w.finish().expect_err("must fail")
        };
        // 30 frames of 24×20 cannot fit a 64-pixel sheet.
        let e = try_write(
            "big.png",
            30,
            FlipbookOptions {
                max_size: Some(64),
                ..Default::default()
            },
        );
        assert!(matches!(e, MediaError::LimitExceeded(_)), "{e}");
        assert!(e.to_string().contains("max-size"), "{e}");
        // One frame does not fit 16 pixels: refused at create.
        let e = try_write(
            "tiny.png",
            1,
            FlipbookOptions {
                max_size: Some(16),
                ..Default::default()
            },
        );
        assert!(matches!(e, MediaError::LimitExceeded(_)), "{e}");
        let e = try_write(
            "v0.png",
            2,
            FlipbookOptions {
                variants: 0,
                ..Default::default()
            },
        );
        assert!(
            matches!(
                e,
                MediaError::BadParameter {
                    name: "variants",
                    ..
                }
            ),
            "{e}"
        );
        let e = try_write(
            "one.png",
            1,
            FlipbookOptions {
                motion: Some(disc_flow()),
                ..Default::default()
            },
        );
        assert!(
            matches!(
                e,
                MediaError::BadParameter {
                    name: "motion-vectors",
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            dir_entries(dir.path()).is_empty(),
            "{:?}",
            dir_entries(dir.path())
        );
    }
}

/// Every shader in `engines/` through a real compiler front end (see engines/README.md).
mod shaders {
    use std::path::PathBuf;

    fn engines() -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../engines"))
    }

    fn read(rel: &str) -> String {
        std::fs::read_to_string(engines().join(rel)).unwrap()
    }

    fn validate(module: &naga::Module, what: &str) {
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(module)
        .unwrap_or_else(|e| panic!("{what}: {e:?}"));
    }

    #[test]
    fn every_engine_file_is_checked() {
        let mut files = Vec::new();
        for dir in std::fs::read_dir(engines()).unwrap() {
            let dir = dir.unwrap().path();
            if dir.is_dir() {
                for f in std::fs::read_dir(&dir).unwrap() {
                    files.push(f.unwrap().path());
                }
            }
        }
        let mut names: Vec<String> = files
            .iter()
            .map(|p| p.strip_prefix(engines()).unwrap().display().to_string())
            .collect();
        names.sort();
        // A new shader needs a check below before it can ship.
        assert_eq!(
            names,
            [
                "godot/flipbook_motion_blend.gdshader",
                "unity/FlipbookMotionBlend.hlsl",
                "unreal/FlipbookMotionBlend.ush",
                "wgsl/flipbook_motion_blend.wgsl",
            ]
        );
    }

    #[test]
    fn wgsl_parses_and_validates() {
        let src = read("wgsl/flipbook_motion_blend.wgsl");
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
        validate(&module, "wgsl");
        assert!(module.entry_points.iter().any(|e| e.name == "fs_main"));
    }

    /// The Godot shading language → Vulkan-style GLSL 450 (the mapping in engines/README.md).
    fn godot_to_glsl(src: &str) -> String {
        let mut samplers = Vec::new();
        let mut block = Vec::new();
        let mut body = Vec::new();
        for line in src.lines() {
            let t = line.trim();
            if t.starts_with("shader_type") || t.starts_with("render_mode") {
                continue;
            }
            if let Some(rest) = t.strip_prefix("uniform ") {
                let decl = rest.split([':', '=', ';']).next().unwrap().trim();
                let (ty, name) = decl.split_once(' ').unwrap();
                if ty == "sampler2D" {
                    samplers.push(name.trim().to_string());
                } else {
                    block.push(format!("    {ty} {};", name.trim()));
                }
                continue;
            }
            body.push(line.to_string());
        }
        let mut out = String::from("#version 450\nlayout(location = 0) in vec2 UV;\nlayout(location = 0) out vec4 COLOR;\n");
        out += &format!(
            "layout(set = 0, binding = 0) uniform Params {{\n{}\n}};\n",
            block.join("\n")
        );
        for (i, s) in samplers.iter().enumerate() {
            out += &format!(
                "layout(set = 0, binding = {}) uniform texture2D {s}_t;\nlayout(set = 0, binding = {}) uniform sampler {s}_s;\n",
                1 + 2 * i,
                2 + 2 * i
            );
        }
        let mut text = body.join("\n").replace("void fragment()", "void main()");
        for s in &samplers {
            text = text.replace(
                &format!("texture({s},"),
                &format!("texture(sampler2D({s}_t, {s}_s),"),
            );
        }
        out + &text
    }

    #[test]
    fn godot_shader_as_glsl() {
        let glsl = godot_to_glsl(&read("godot/flipbook_motion_blend.gdshader"));
        let mut frontend = naga::front::glsl::Frontend::default();
        let opts = naga::front::glsl::Options::from(naga::ShaderStage::Fragment);
        let module = frontend
            .parse(&opts, &glsl)
            .unwrap_or_else(|e| panic!("{}\n{}", e.emit_to_string(&glsl), glsl));
        validate(&module, "godot");
    }

    fn glslang() -> Option<PathBuf> {
        let ok = std::process::Command::new("glslangValidator")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
        if !ok {
            println!("skipped: glslangValidator not on PATH (Debian package glslang-tools)");
        }
        ok.then(|| PathBuf::from("glslangValidator"))
    }

    fn check_hlsl(source: &str, entry: &str) {
        let Some(tool) = glslang() else { return };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("shader.frag.hlsl");
        std::fs::write(&path, source).unwrap();
        let out = std::process::Command::new(tool)
            .args(["-D", "-S", "frag", "-e", entry, "-V"])
            .arg(&path)
            .args(["-o"])
            .arg(dir.path().join("out.spv"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}\n{}\n{source}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    #[test]
    fn unity_custom_function_hlsl() {
        let src = read("unity/FlipbookMotionBlend.hlsl")
            + "\nTexture2D Col; Texture2D Mv; SamplerState Smp;\n\
               float4 main(float2 uv : TEXCOORD0) : SV_Target {\n\
               float4 o; FlipbookMotionBlend_float(Col, Mv, Smp, uv, float2(8, 8), 64, 0.05, 3.25, 1, o); return o; }\n";
        check_hlsl(&src, "main");
    }

    #[test]
    fn unreal_custom_node_hlsl() {
        let body = read("unreal/FlipbookMotionBlend.ush");
        let src = format!(
            "#define Texture2DSample(t, s, uv) t.Sample(s, uv)\n\
             Texture2D ColorSheet; SamplerState ColorSheetSampler;\n\
             Texture2D MotionSheet; SamplerState MotionSheetSampler;\n\
             float4 CustomExpression0(float2 UV, float2 SubImages, float Frames, float Strength, float SubImageIndex, float Loop)\n{{\n{body}\n}}\n\
             float4 main(float2 uv : TEXCOORD0) : SV_Target {{ return CustomExpression0(uv, float2(8, 8), 64, 0.05, 3.25, 1); }}\n"
        );
        check_hlsl(&src, "main");
    }
}

/// A destination that cannot be written is refused when the writer is created (not after
/// the render, as a flipbook's files are only made by `finish`), and
/// [`check_output`] finds it without creating anything.
mod output_checks {
    use super::*;

    #[test]
    fn unwritable_destinations_are_refused_up_front() {
        let t = tempfile::tempdir().unwrap();
        let file = t.path().join("plain.txt");
        std::fs::write(&file, b"not a directory").unwrap();
        let size = Size::new(8, 8).unwrap();
        let opts = WriteOptions::default();
        for name in [
            "x.png",
            "sub/x.png",
            "x.mp4",
            "x.gif",
            "seq/%04d.png",
            "seq/",
        ] {
            let path = file.join(name);
            let e = check_output(&path, &opts).expect_err(name).to_string();
            assert!(e.contains("not a directory"), "{name}: {e}");
            let e = create(&path, size, &opts).err().expect(name).to_string();
            assert!(e.contains("not a directory"), "{name}: {e}");
        }
        #[cfg(target_os = "linux")]
        {
            let e = create(Path::new("/proc/ignis-no-such/x.png"), size, &opts)
                .err()
                .expect("/proc is not writable");
            assert!(e.to_string().contains("cannot write in /proc"), "{e}");
        }
        assert_eq!(dir_entries(t.path()), vec!["plain.txt".to_string()]);
    }

    #[test]
    fn checking_creates_nothing_and_names_the_format() {
        let t = tempfile::tempdir().unwrap();
        let opts = WriteOptions::default();
        let f = check_output(&t.path().join("a/b/x.png"), &opts).unwrap();
        assert_eq!(f, Format::Flipbook);
        let f = check_output(&t.path().join("a/frames/%04d.exr"), &opts).unwrap();
        assert_eq!(f, Format::ExrSequence);
        assert!(check_output(&t.path().join("x.xyz"), &opts).is_err());
        assert!(check_output(&t.path().join("f/%d%d.png"), &opts).is_err());
        let bad_fps = WriteOptions {
            fps: 0.0,
            ..WriteOptions::default()
        };
        assert!(check_output(&t.path().join("x.mp4"), &bad_fps).is_err());
        assert!(
            dir_entries(t.path()).is_empty(),
            "{:?}",
            dir_entries(t.path())
        );
    }
}
