//! Parsers for the range and rectangle arguments the commands share (`--range`, `--seconds`,
//! `--crop`, `--chunk`, eigen's frame spans): one syntax and one set of messages, so a
//! range means the same thing in every command.
//!
//! A range is `START..END` with END excluded; [`frame_range`] and [`seconds_range`] also take
//! `START..` and `..END`. Frame numbers are whole numbers: `1.5..3` is refused, not
//! truncated. Errors name the argument text and say how to write it.

use ignis_core::atomic::AtomicFile;
use ignis_media::Rect;
use std::ops::Range;
use std::str::FromStr;

const EXAMPLE: &str = "e.g. 100..220 (START included, END excluded)";

/// The two bounds of `A..B`, either of which may be left out (`None`).
fn bounds<T: FromStr>(s: &str, what: &str) -> Result<(Option<T>, Option<T>), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("`{s}` is not a range A..B; {EXAMPLE}"))?;
    let one = |v: &str, which: &str| -> Result<Option<T>, String> {
        let v = v.trim();
        if v.is_empty() {
            return Ok(None);
        }
        v.parse::<T>()
            .map(Some)
            .map_err(|_| format!("range `{s}`: {which} `{v}` is not {what}; {EXAMPLE}"))
    };
    Ok((one(a, "START")?, one(b, "END")?))
}

/// `A..B` with both bounds given (no check that A < B: [`frame_span`] and the callers of a
/// chunk check that against their own limits).
pub fn closed_range<T: FromStr>(s: &str, what: &str) -> Result<(T, T), String> {
    match bounds::<T>(s, what)? {
        (Some(a), Some(b)) => Ok((a, b)),
        _ => Err(format!(
            "range `{s}` needs both bounds: write it as A..B; {EXAMPLE}"
        )),
    }
}

fn non_empty<T: PartialOrd>(s: &str, start: T, end: Option<T>) -> Result<(), String> {
    match end {
        Some(e) if e <= start => Err(format!(
            "range `{s}` is empty: END must be greater than START; {EXAMPLE}"
        )),
        _ => Ok(()),
    }
}

const FRAME: &str = "a frame number (a whole number, 0 or more)";

/// A frame range `A..B`, `A..` or `..B` as (start, end); START defaults to 0, a missing END
/// reads to the last frame. Refuses an empty range.
pub fn frame_range(s: &str) -> Result<(u64, Option<u64>), String> {
    let (a, b) = bounds::<u64>(s, FRAME)?;
    let start = a.unwrap_or(0);
    non_empty(s, start, b)?;
    Ok((start, b))
}

/// A time range in seconds, `A..B`, `A..` or `..B`, as (start, end): finite, 0 or more,
/// not empty.
pub fn seconds_range(s: &str) -> Result<(f64, Option<f64>), String> {
    let (a, b) = bounds::<f64>(s, "a number of seconds")?;
    for x in [a, b].into_iter().flatten() {
        if !(x.is_finite() && x >= 0.0) {
            return Err(format!(
                "range `{s}`: {x} is not a time of 0 seconds or more; e.g. 2..4.5"
            ));
        }
    }
    let start = a.unwrap_or(0.0);
    non_empty(s, start, b)?;
    Ok((start, b))
}

/// Reads a text file the user named (`what`: "fire file", "clips file", ...) with a bound
/// and without blocking ([`ignis_core::textfile::read_text`]); a path that is not there
/// says so, and `instead`, what to give instead.
pub fn read_user_text(path: &std::path::Path, what: &str, instead: &str) -> anyhow::Result<String> {
    ignis_core::atomic::record_input(path);
    ignis_core::textfile::read_text(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            anyhow::anyhow!(
                "{what} {} does not exist; check the path, or {instead}",
                path.display()
            )
        } else {
            anyhow::anyhow!("{what} {}: {e}", path.display())
        }
    })
}

/// The file standing where `dir` or one of its parents should be a folder, if any (what
/// makes creating `dir` fail with the system's unhelpful "File exists" / "Not a
/// directory").
pub fn file_in_the_way(dir: &std::path::Path) -> Option<&std::path::Path> {
    dir.ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .find(|a| a.metadata().is_ok_and(|m| !m.is_dir()))
}

/// Refuses a text output path below a file (checked before the work that fills it).
pub fn check_text_output(path: &std::path::Path) -> anyhow::Result<()> {
    if let Some(file) = path.parent().and_then(file_in_the_way) {
        anyhow::bail!(
            "{} is a file, not a folder, so {} cannot be written there; choose a path inside \
             a folder",
            file.display(),
            path.display()
        );
    }
    Ok(())
}

/// A text output the user named (`--collisions`, `volume scene -o`) as an atomic temporary
/// holding `text`, to commit once everything else is written: its folder is made when
/// missing, as every output's is, and a file standing where a folder must be is named.
pub fn text_output(path: &std::path::Path, text: &str) -> anyhow::Result<AtomicFile> {
    use anyhow::Context;
    check_text_output(path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the folder {}", dir.display()))?;
    }
    let mut f = AtomicFile::create(path).with_context(|| format!("writing {}", path.display()))?;
    std::io::Write::write_all(f.writer(), text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(f)
}

/// `rect`'s size when it lies inside `path`'s frame of `size`; else an error naming the
/// frame's size and what fits.
pub fn crop_inside(
    rect: &Rect,
    size: ignis_media::Size,
    path: &std::path::Path,
) -> anyhow::Result<ignis_media::Size> {
    ignis_media::check_crop(rect, size).map_err(|_| {
        let (w, h) = (size.width, size.height);
        anyhow::anyhow!(
            "crop {},{},{},{} reaches past the {w}x{h} frame of {}; give X,Y,WIDTH,HEIGHT with \
             X + WIDTH ≤ {w} and Y + HEIGHT ≤ {h}",
            rect.x,
            rect.y,
            rect.width,
            rect.height,
            path.display()
        )
    })
}

/// A frame span `A..B` with both bounds and A < B (eigen's and `ignis loop`'s `--range`).
pub fn frame_span(s: &str) -> Result<Range<usize>, String> {
    let (a, b) = closed_range::<usize>(s, FRAME)?;
    non_empty(s, a, Some(b))?;
    Ok(a..b)
}

/// A crop rectangle in pixels, WIDTH and HEIGHT above 0, in any of the forms people copy
/// from other tools: `X,Y,WIDTH,HEIGHT` (ours), `WIDTHxHEIGHT+X+Y` (an X11 / ImageMagick
/// geometry, as compositing and image tools print a region) or `WIDTH:HEIGHT:X:Y`, with
/// or without `crop=` in front (what ffmpeg's `cropdetect` prints for letterbox bars,
/// pasted as is).
pub fn crop(s: &str) -> Result<Rect, String> {
    let bad = || {
        format!(
            "crop `{s}`: write X,Y,WIDTH,HEIGHT in pixels with WIDTH, HEIGHT > 0, e.g. \
             140,120,200,300 (or the same as 200x300+140+120, or ffmpeg cropdetect's \
             crop=200:300:140:120)"
        )
    };
    let t = s.trim();
    let t = t.strip_prefix("crop=").unwrap_or(t);
    // ffmpeg's W:H:X:Y and a geometry's WxH+X+Y give the size first; ours the corner
    let (parts, size_first): (Vec<&str>, bool) = if t.contains(':') {
        (t.split(':').collect(), true)
    } else if let Some((w, rest)) = t.split_once(['x', 'X']) {
        (std::iter::once(w).chain(rest.split('+')).collect(), true)
    } else {
        (t.split(',').collect(), false)
    };
    let v: Vec<u32> = parts
        .iter()
        .map(|x| x.trim().parse::<u32>().ok())
        .collect::<Option<_>>()
        .ok_or_else(bad)?;
    let v = match (size_first, &v[..]) {
        (true, &[w, h, x, y]) => vec![x, y, w, h],
        _ => v,
    };
    match v[..] {
        [x, y, width, height] if width > 0 && height > 0 => Ok(Rect {
            x,
            y,
            width,
            height,
        }),
        _ => Err(bad()),
    }
}

/// A frame rate as people write it: a video rate of the NTSC family by its usual decimal and
/// its exact fraction (`29.97 (30000/1001)`), any other with at most three decimals (`25`,
/// `15.019`), where `{}` printed every digit of the `f64` (`29.97002997002997`).
pub fn fps_text(fps: f64) -> String {
    let short = |v: f64| {
        let s = format!("{v:.3}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    };
    for n in [24u32, 30, 48, 60, 120, 240] {
        let ntsc = f64::from(n) * 1000.0 / 1001.0;
        if (fps - ntsc).abs() <= 1e-9 * ntsc {
            return format!("{} ({}/1001)", short(ntsc), n * 1000);
        }
    }
    short(fps)
}

/// `--sequence-fps`: a frame rate as `24`, `29.97` or `24000/1001`, within
/// [`ignis_media::SEQUENCE_FPS_RANGE`].
pub fn sequence_fps(s: &str) -> Result<f64, String> {
    let (lo, hi) = (
        *ignis_media::SEQUENCE_FPS_RANGE.start(),
        *ignis_media::SEQUENCE_FPS_RANGE.end(),
    );
    let how = "write it as 24, 25, 29.97 or 24000/1001";
    let number = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let fps = match s.split_once('/') {
        Some((n, d)) => match (number(n), number(d)) {
            (Some(n), Some(d)) if d > 0.0 => n / d,
            _ => return Err(format!("`{s}` is not a frame rate; {how}")),
        },
        None => number(s).ok_or_else(|| format!("`{s}` is not a frame rate; {how}"))?,
    };
    if !(lo..=hi).contains(&fps) {
        return Err(format!(
            "{s} fps is outside {lo}..{hi}; give the rate the sequence was shot or rendered at ({how})"
        ));
    }
    Ok(fps)
}

/// The rate an image-sequence input is read at (`--sequence-fps`), for the commands that
/// read footage.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct SequenceFps {
    /// Frame rate of an image-sequence input (default: an EXR sequence's framesPerSecond,
    /// else 30, as PNG, JPEG and TIFF store none), as an editor's "interpret footage" or
    /// ffmpeg's -framerate: 24, 25, 29.97, 24000/1001. Seconds, durations and the output's
    /// rate follow it; videos, GIFs and flipbooks keep their own rates.
    #[arg(long, value_name = "FPS", value_parser = sequence_fps)]
    pub sequence_fps: Option<f64>,
}

impl SequenceFps {
    /// Sets the rate for this process, before anything is read, and warns (stderr) for
    /// each of `inputs` that has a rate of its own, which is kept.
    pub fn apply(&self, inputs: &[&std::path::Path]) -> anyhow::Result<()> {
        let Some(fps) = self.sequence_fps else {
            return Ok(());
        };
        ignis_media::set_sequence_fps(fps)?;
        for info in inputs.iter().filter_map(|p| ignis_media::probe(p).ok()) {
            if let Some(w) = own_rate_warning(fps, &info) {
                eprintln!("{w}");
            }
        }
        Ok(())
    }

    /// A line for a command whose output's timing follows the input's rate, when `info`
    /// is an image sequence read at the default rate because neither `--sequence-fps` nor
    /// its files gave one: a 24-fps plate read at 30 plays fast.
    pub fn default_rate_note(&self, info: &ignis_media::SourceInfo) -> Option<String> {
        (info.decoder == ignis_media::Decoder::ImageSequence
            && self.sequence_fps.is_none()
            && !info.rate_stated)
            .then(|| {
                format!(
                    "rate: the sequence states no frame rate, so it is read at {} fps; \
                 --sequence-fps gives the rate it was shot or rendered at",
                    fps_text(info.fps)
                )
            })
    }
}

/// The warning for `--sequence-fps FPS` given with `info`'s source when it is not an image
/// sequence or still (a video, GIF or flipbook keeps its own rate).
fn own_rate_warning(fps: f64, info: &ignis_media::SourceInfo) -> Option<String> {
    use ignis_media::Decoder;
    (!matches!(info.decoder, Decoder::ImageSequence | Decoder::Image)).then(|| {
        format!(
            "warning: --sequence-fps {} is for image sequences; {} has its own rate, {} fps, \
             which is kept (to store another, `ignis convert` it with --fps)",
            fps_text(fps),
            info.path.display(),
            fps_text(info.fps)
        )
    })
}

/// An ordinal for messages: `2nd`, `3rd`, `4th`, `11th`, `21st`.
pub fn nth(k: u32) -> String {
    let suffix = match (k % 10, k % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{k}{suffix}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn frame_ranges() {
        assert_eq!(frame_range("100..220"), Ok((100, Some(220))));
        assert_eq!(frame_range(" 5 .. "), Ok((5, None)));
        assert_eq!(frame_range("..7"), Ok((0, Some(7))));
        assert_eq!(frame_range(".."), Ok((0, None)));
        // the old `a as u64` truncation: refused with the reason
        let e = frame_range("1.5..3").unwrap_err();
        assert!(e.contains("`1.5` is not a frame number"), "{e}");
        assert!(frame_range("-1..3").unwrap_err().contains("START `-1`"));
        assert!(frame_range("50..50").unwrap_err().contains("empty"));
        assert!(frame_range("9..3").unwrap_err().contains("empty"));
        assert!(frame_range("3-9").unwrap_err().contains("A..B"));
        assert!(frame_range("1..2..3").unwrap_err().contains("END `2..3`"));
    }

    #[test]
    fn frame_rates_as_people_write_them() {
        assert_eq!(fps_text(30000.0 / 1001.0), "29.97 (30000/1001)");
        assert_eq!(fps_text(24000.0 / 1001.0), "23.976 (24000/1001)");
        assert_eq!(fps_text(60000.0 / 1001.0), "59.94 (60000/1001)");
        assert_eq!(fps_text(25.0), "25");
        assert_eq!(fps_text(30.0), "30");
        assert_eq!(fps_text(12.5), "12.5");
        assert_eq!(fps_text(15.018773466833542), "15.019");
        // an average near an NTSC rate is not one
        assert_eq!(fps_text(29.971), "29.971");
    }

    #[test]
    fn seconds_ranges() {
        assert_eq!(seconds_range("2..4.5"), Ok((2.0, Some(4.5))));
        assert_eq!(seconds_range("1.25.."), Ok((1.25, None)));
        assert!(seconds_range("-1..2")
            .unwrap_err()
            .contains("0 seconds or more"));
        assert!(seconds_range("0..inf")
            .unwrap_err()
            .contains("0 seconds or more"));
        assert!(seconds_range("NaN..2")
            .unwrap_err()
            .contains("0 seconds or more"));
        assert!(seconds_range("3..1").unwrap_err().contains("empty"));
        assert!(seconds_range("a..1").unwrap_err().contains("START `a`"));
    }

    #[test]
    fn spans_and_closed_ranges() {
        assert_eq!(frame_span("1..11"), Ok(1..11));
        assert!(frame_span("5..").unwrap_err().contains("both bounds"));
        assert!(frame_span("5..5").unwrap_err().contains("empty"));
        assert_eq!(closed_range::<u32>("20..20", FRAME), Ok((20, 20)));
        assert!(closed_range::<u32>("5-9", FRAME)
            .unwrap_err()
            .contains("A..B"));
    }

    #[test]
    fn crops() {
        assert_eq!(
            crop("140, 120,200,300"),
            Ok(Rect {
                x: 140,
                y: 120,
                width: 200,
                height: 300
            })
        );
        for bad in [
            "1,2,3",
            "1,2,3,4,5",
            "1,2,0,4",
            "1,2,3,0",
            "a,2,3,4",
            "-1,2,3,4",
            "",
        ] {
            assert!(crop(bad).unwrap_err().contains("X,Y,WIDTH,HEIGHT"), "{bad}");
        }
        // the forms other tools print: a geometry, and ffmpeg cropdetect's line
        let r = Rect {
            x: 140,
            y: 120,
            width: 200,
            height: 300,
        };
        for form in [
            "200x300+140+120",
            "200X300+140+120",
            "crop=200:300:140:120",
            " 200:300:140:120 ",
        ] {
            assert_eq!(crop(form), Ok(r), "{form}");
        }
        for bad in [
            "200x300",
            "200x300+140",
            "200x300+140+120+1",
            "200x300-140-120",
            "0x300+1+2",
            "200:300:140",
            "crop=200:0:1:2",
            "x+1+2",
            "200x300++120",
        ] {
            let e = crop(bad).unwrap_err();
            assert!(e.contains("crop=200:300:140:120"), "{bad}: {e}");
        }
    }

    proptest! {
        #[test]
        fn frame_ranges_round_trip(a in 0u64..1 << 40, len in 1u64..1 << 20, open_end: bool) {
            let s = if open_end { format!("{a}..") } else { format!("{a}..{}", a + len) };
            let want = (a, (!open_end).then_some(a + len));
            prop_assert_eq!(frame_range(&s), Ok(want));
        }

        #[test]
        fn frame_ranges_never_panic_and_are_never_empty(s in "[0-9.\\- a]{0,12}") {
            if let Ok((a, Some(b))) = frame_range(&s) {
                prop_assert!(a < b);
            }
        }

        #[test]
        fn seconds_ranges_are_finite_ordered_and_non_negative(s in "[0-9.e\\-inf ]{0,14}") {
            if let Ok((a, b)) = seconds_range(&s) {
                prop_assert!(a.is_finite() && a >= 0.0);
                if let Some(b) = b {
                    prop_assert!(b.is_finite() && b > a);
                }
            }
        }

        #[test]
        fn crops_round_trip(x: u32, y: u32, w in 1u32.., h in 1u32..) {
            for form in [
                format!("{x},{y},{w},{h}"),
                format!("{w}x{h}+{x}+{y}"),
                format!("crop={w}:{h}:{x}:{y}"),
            ] {
                let r = crop(&form).unwrap();
                prop_assert_eq!((r.x, r.y, r.width, r.height), (x, y, w, h));
            }
        }

        #[test]
        fn crops_of_any_text_never_panic(s in "[0-9x+:,=a-z ]{0,20}") {
            if let Ok(r) = crop(&s) {
                prop_assert!(r.width > 0 && r.height > 0);
            }
        }
    }
}
