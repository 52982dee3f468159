//! When each frame of a video is shown, and whether its frame rate holds.
//!
//! A phone records at a variable frame rate: in low light (a fire at night) it holds each
//! frame longer, 30 fps becoming 24 or 15, and it drops frames when busy. A player shows
//! every frame at its own time; a reader that counts frames at the average rate
//! ([`SourceInfo::fps`](super::SourceInfo::fps)) plays a stretch shot at half the rate
//! twice as fast as it happened. [`FrameTiming`] keeps the frames' presentation times and
//! finds the steps between frames that are not at the clip's nominal rate.

use std::ops::Range;
use std::path::Path;

use ignis_core::loopq::median;

use crate::error::Result;

/// A step longer than this many nominal frame durations (or shorter than its inverse) is
/// uneven on its own: at 2 a frame was dropped, and the picture jumps two frames' worth.
pub const JUMP_RATIO: f64 = 1.5;
/// Steps whose local rate (the median duration of the [`LOCAL_STEPS`] steps around them)
/// is off the nominal duration by more than this share are uneven: the clip's rate changed
/// there (30 → 24 fps is 25 % off). Single steps jitter by more than this in phone footage
/// (an Android camera's timestamps wander by ±10 %), which no one sees: the median over
/// the neighbours ignores that.
pub const RATE_TOLERANCE: f64 = 0.1;
/// Steps in the local median of [`RATE_TOLERANCE`]: odd, so a change of rate is placed at
/// the step where it happens.
pub const LOCAL_STEPS: usize = 9;
/// The most frame times kept (4 h at 60 fps, 128 MiB): a damaged header that claims more
/// frames gets no timing, not an allocation of its claim.
pub const MAX_TIMED_FRAMES: usize = 1 << 24;

/// The presentation times of a clip's frames (seconds, ascending; at least two), with
/// its uneven steps and nominal step worked out once.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameTiming {
    times: Vec<f64>,
    uneven: Vec<usize>,
    nominal_step: f64,
    numbered: bool,
}

impl FrameTiming {
    /// Timing from frame times in any order (sorted here; decoding order differs from
    /// presentation order with B-frames); `None` with fewer than two, any not finite, or
    /// more than `MAX_TIMED_FRAMES`.
    pub fn new(mut times: Vec<f64>) -> Option<FrameTiming> {
        if times.len() < 2 || times.len() > MAX_TIMED_FRAMES || times.iter().any(|t| !t.is_finite())
        {
            return None;
        }
        times.sort_by(f64::total_cmp);
        let steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        let uneven = uneven_steps(&steps);
        let nominal_step = nominal_step(&steps, &uneven);
        Some(FrameTiming {
            times,
            uneven,
            nominal_step,
            numbered: false,
        })
    }

    /// Timing from an image sequence's frame times, one frame every `step` seconds but
    /// where frames are missing ([`frame_timing`]): its uneven steps are exactly those
    /// not `step` long (as [`JUMP_RATIO`] judges), with no local rate to estimate, since
    /// the numbers say it. `None` as [`Self::new`], or for a `step` not above 0.
    pub(crate) fn numbered(times: Vec<f64>, step: f64) -> Option<FrameTiming> {
        let t = FrameTiming::new(times)?;
        if !(step > 0.0 && step.is_finite()) {
            return None;
        }
        let uneven = t
            .steps()
            .iter()
            .enumerate()
            .filter(|(_, &s)| !(1.0 / JUMP_RATIO..=JUMP_RATIO).contains(&(s / step)))
            .map(|(i, _)| i)
            .collect();
        Some(FrameTiming {
            uneven,
            nominal_step: step,
            numbered: true,
            ..t
        })
    }

    /// Whether the times come from an image sequence's frame numbers, where frames are
    /// missing from it (its uneven steps are the gaps), rather than from a video's
    /// timestamps.
    pub fn from_frame_numbers(&self) -> bool {
        self.numbered
    }

    /// The frame times, ascending.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Always false (a timing has at least two frames).
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The timing of frames `range` alone (`None` when fewer than two of them exist).
    pub fn window(&self, range: Range<usize>) -> Option<FrameTiming> {
        let r = range.start.min(self.len())..range.end.min(self.len());
        let times = self.times[r].to_vec();
        if self.numbered {
            FrameTiming::numbered(times, self.nominal_step)
        } else {
            FrameTiming::new(times)
        }
    }

    /// The steps between consecutive frames, seconds (`len() - 1` values).
    pub fn steps(&self) -> Vec<f64> {
        self.times.windows(2).map(|w| w[1] - w[0]).collect()
    }

    /// The clip's nominal frame duration: the mean of the steps at the nominal rate (those
    /// not in [`Self::uneven_steps`]; all steps when none is). A mean, not the median: a
    /// 29.97-fps clip in a 1-ms time base steps 33 or 34 ms, and its median step, 33 ms,
    /// is 1 % fast.
    pub fn nominal_step(&self) -> f64 {
        self.nominal_step
    }

    /// The nominal frame rate, `1 / nominal_step` (the rate most of the clip plays at),
    /// taken as the standard rate it is within 0.1 % of (a whole number, or one over
    /// 1.001 of one: 23.976, 29.97, 59.94), as timestamps rounded to a time base are.
    pub fn nominal_fps(&self) -> f64 {
        standard_rate(1.0 / self.nominal_step())
    }

    /// The average frame rate over the clip: steps over the time they span.
    pub fn average_fps(&self) -> f64 {
        let span = self.times[self.len() - 1] - self.times[0];
        (self.len() - 1) as f64 / span
    }

    /// The steps (index `i`: from frame `i` to frame `i + 1`) that do not play at the
    /// nominal rate: a jump (`JUMP_RATIO`: a dropped frame, a held one, two frames at one
    /// time) or a stretch at another rate (`RATE_TOLERANCE` on the local median). Empty
    /// for a clip at a constant rate, however its timestamps are rounded.
    pub fn uneven_steps(&self) -> &[usize] {
        &self.uneven
    }

    /// Whether some step does not play at the nominal rate ([`Self::uneven_steps`]).
    pub fn is_variable(&self) -> bool {
        !self.uneven.is_empty()
    }

    /// The frame shown nearest `seconds` after the first frame (the first frame at 0):
    /// the number of midpoints between consecutive frames at or before it, as a constant
    /// rate's `round(seconds × fps)`; past the last frame, one more frame per nominal step
    /// (so an end just after the last frame is the frame count).
    pub fn frame_at(&self, seconds: f64) -> u64 {
        let at = self.times[0] + seconds;
        let n = self.len();
        let last = self.times[n - 1];
        if at >= last {
            let beyond = ((at - last) / self.nominal_step).round();
            return (n - 1) as u64 + if beyond.is_finite() { beyond as u64 } else { 0 };
        }
        self.times
            .windows(2)
            .take_while(|w| 0.5 * (w[0] + w[1]) <= at)
            .count() as u64
    }

    /// How many times each of frames `range` is written to play at `fps` as a player shows
    /// them (each frame held until the next one's time: written at every tick
    /// `times[start] + k / fps` from its own time to the next frame's, 0 times when the
    /// ticks step over it); the range's last frame is held until the next frame's time,
    /// at most one nominal step (its end cuts there). `Err`
    /// with the number of frames that would be written when that is more than `most` (a
    /// gap of hours in the timestamps, a damaged file), before any is counted.
    pub fn holds(
        &self,
        range: Range<usize>,
        fps: f64,
        most: u64,
    ) -> std::result::Result<Vec<u32>, f64> {
        let r = range.start.min(self.len())..range.end.min(self.len());
        let mut out = vec![0u32; r.len()];
        if r.is_empty() || fps.is_nan() || fps <= 0.0 {
            return Ok(out);
        }
        let t0 = self.times[r.start];
        // the last frame is held until the next one, at most a nominal step (a range's
        // end cuts there: the next frame may come an hour later)
        let last = self.times[r.end - 1];
        let next = self.times.get(r.end).map_or(f64::INFINITY, |&t| t - last);
        let end = last + next.min(self.nominal_step);
        // a tick within a microsecond of a frame's time shows that frame
        const EPS: f64 = 1e-6;
        let written = ((end - EPS - t0) * fps).ceil();
        if written.is_nan() || written > most as f64 {
            return Err(written);
        }
        let mut i = r.start;
        for k in 0u64.. {
            let tick = t0 + k as f64 / fps;
            if tick >= end - EPS {
                break;
            }
            while i + 1 < r.end && self.times[i + 1] <= tick + EPS {
                i += 1;
            }
            out[i - r.start] += 1;
        }
        Ok(out)
    }

    /// The longest step among frames `range` (seconds) and the frame it starts at.
    pub fn longest_step(&self, range: Range<usize>) -> Option<(usize, f64)> {
        let r = range.start.min(self.len())..range.end.min(self.len());
        (r.start..r.end.saturating_sub(1))
            .map(|i| (i, self.times[i + 1] - self.times[i]))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The shortest and the longest step, seconds.
    pub fn step_range(&self) -> (f64, f64) {
        self.steps()
            .into_iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), s| {
                (lo.min(s), hi.max(s))
            })
    }
}

/// `fps`, or the standard rate within 0.1 % of it (`n` or `n / 1.001` frames a second,
/// `n` up to 240).
fn standard_rate(fps: f64) -> f64 {
    let n = fps.round();
    let ntsc = (fps * 1.001).round() / 1.001;
    [n, ntsc]
        .into_iter()
        .filter(|&r| (1.0..=240.0).contains(&r) && (fps / r - 1.0).abs() <= 1e-3)
        .min_by(|a, b| (fps - a).abs().total_cmp(&(fps - b).abs()))
        .unwrap_or(fps)
}

/// [`FrameTiming::uneven_steps`] of `steps` (at least one).
fn uneven_steps(steps: &[f64]) -> Vec<usize> {
    let nominal = median(&mut steps.to_vec());
    if nominal <= 0.0 {
        // most frames share a time: no rate to hold
        return (0..steps.len()).collect();
    }
    let half = LOCAL_STEPS / 2;
    let mut local = Vec::with_capacity(LOCAL_STEPS);
    (0..steps.len())
        .filter(|&i| {
            let r = steps[i] / nominal;
            if !(1.0 / JUMP_RATIO..=JUMP_RATIO).contains(&r) {
                return true;
            }
            local.clear();
            local
                .extend_from_slice(&steps[i.saturating_sub(half)..(i + half + 1).min(steps.len())]);
            (median(&mut local) / nominal - 1.0).abs() > RATE_TOLERANCE
        })
        .collect()
}

/// [`FrameTiming::nominal_step`]: the mean of `steps` less the `uneven` ones (ascending),
/// of all when every step is uneven.
fn nominal_step(steps: &[f64], uneven: &[usize]) -> f64 {
    let mut skip = uneven.iter().peekable();
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, s) in steps.iter().enumerate() {
        if skip.next_if_eq(&&i).is_some() {
            continue;
        }
        sum += s;
        n += 1;
    }
    if n == 0 {
        steps.iter().sum::<f64>() / steps.len() as f64
    } else {
        sum / n as f64
    }
}

/// When `path`'s frames are shown, from its container's timestamps (callers treat an
/// error as no timing: the frames still read, at the average rate): an MP4's sample table
/// on the built-in path, the packets' timestamps (`ffprobe`, demuxing only) for what
/// ffmpeg reads. `None` where there are none to read or they do not match the frames
/// read: stills, image sequences with every frame (one rate for all), GIFs (their delays
/// are whole hundredths of a second, so 30 fps alternates 3- and 4-cs frames that are not
/// a change of rate), files whose timestamps are missing or whose packets are not one per
/// frame. A sequence with frames missing is timed by its frame numbers, each gap a longer
/// step ([`FrameTiming::from_frame_numbers`]).
pub fn frame_timing(path: &Path) -> Result<Option<FrameTiming>> {
    use super::Probed;
    let probed = super::probe_inner(path, super::ffmpeg_available())?;
    let times = match &probed {
        Probed::Mp4(info, p) => super::h264::sample_times(path, p, info.frame_count)?,
        Probed::Ffmpeg(info, plan) => super::ffmpeg::timed_frames(path, plan, info.frame_count)?,
        Probed::Sequence(info, _, numbers) => {
            return Ok(numbers
                .as_deref()
                .and_then(|n| super::sequence::gap_times(n, info.fps))
                .and_then(|t| FrameTiming::numbered(t, 1.0 / info.fps)))
        }
        Probed::Image(_) | Probed::Gif(_) | Probed::Flipbook(..) => None,
    };
    Ok(times.and_then(FrameTiming::new))
}

/// How many frames the data of a video read through ffmpeg holds: its stream's packets
/// (demuxing only, cached with the frame times), which fall short of the count its header
/// states when the file is cut short (an incomplete download whose index came first).
/// `None` for everything else: the built-in MP4 reader refuses a file whose data is cut
/// short, and sequences, images, GIFs and flipbooks are counted from what is there.
pub fn frames_in_data(path: &Path) -> Result<Option<u64>> {
    match super::probe_inner(path, super::ffmpeg_available())? {
        super::Probed::Ffmpeg(_, plan) => super::ffmpeg::counted_packets(path, &plan),
        _ => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(steps: &[f64]) -> FrameTiming {
        let mut t = vec![0.0];
        for s in steps {
            t.push(t.last().unwrap() + s);
        }
        FrameTiming::new(t).unwrap()
    }

    #[test]
    fn a_constant_rate_is_even_however_it_is_rounded() {
        // 29.97 fps in a 1-ms time base: 33 and 34 ms steps
        let t: Vec<f64> = (0..300)
            .map(|i| ((i as f64 * 1001.0 / 30.0).round()) / 1000.0)
            .collect();
        let t = FrameTiming::new(t).unwrap();
        assert!(t.uneven_steps().is_empty());
        assert!(!t.is_variable());
        assert!(
            (t.average_fps() - 29.97).abs() < 0.01,
            "{}",
            t.average_fps()
        );
        assert_eq!(t.nominal_fps(), 30.0 / 1.001);
        // and a phone's timestamps wandering by ±12 % from frame to frame
        let wander: Vec<f64> = (0..300)
            .map(|i| (1.0 + 0.12 * ((i * 7 % 5) as f64 - 2.0) / 2.0) / 30.0)
            .collect();
        assert!(at(&wander).uneven_steps().is_empty());
    }

    #[test]
    fn a_dropped_frame_and_a_slower_stretch_are_uneven() {
        let mut steps = vec![1.0 / 30.0; 100];
        steps[20] = 2.0 / 30.0; // a dropped frame
        for s in &mut steps[60..80] {
            *s = 1.0 / 24.0; // low light: 24 fps
        }
        let t = at(&steps);
        assert_eq!(t.nominal_fps(), 30.0);
        let u = t.uneven_steps();
        let mut want = vec![20];
        want.extend(60..80);
        assert_eq!(u, want, "exactly the dropped frame and the 24-fps stretch");
        assert!(t.is_variable());
        let (lo, hi) = t.step_range();
        assert!((lo - 1.0 / 30.0).abs() < 1e-12 && (hi - 2.0 / 30.0).abs() < 1e-12);
        // a window of the even part is even
        assert!(!t.window(25..60).unwrap().is_variable());
        assert!(t.window(5..6).is_none());
    }

    /// A sequence's gaps are its uneven steps however many there are (the local medians
    /// of a video's timing would take two gaps in four steps for its rate), in any window.
    #[test]
    fn numbered_timing_is_uneven_exactly_at_the_gaps() {
        let times: Vec<f64> = [0.0, 1.0, 2.0, 4.0, 7.0].iter().map(|n| n / 30.0).collect();
        assert_eq!(FrameTiming::new(times.clone()).unwrap().uneven_steps(), [3]);
        let t = FrameTiming::numbered(times, 1.0 / 30.0).unwrap();
        assert_eq!(t.uneven_steps(), [2, 3]);
        assert_eq!(t.nominal_fps(), 30.0);
        assert!(t.from_frame_numbers());
        let w = t.window(1..5).unwrap();
        assert_eq!(
            (w.uneven_steps(), w.from_frame_numbers()),
            (&[1, 2][..], true)
        );
        assert!(!t.window(0..3).unwrap().is_variable());
        assert!(FrameTiming::numbered(vec![0.0, 1.0], 0.0).is_none());
        assert!(!FrameTiming::new(vec![0.0, 1.0])
            .unwrap()
            .from_frame_numbers());
    }

    #[test]
    fn nominal_rates_are_the_standard_ones_they_are_near() {
        assert_eq!(standard_rate(24.999999999), 25.0);
        assert_eq!(standard_rate(23.9761), 24.0 / 1.001);
        assert_eq!(standard_rate(59.94), 60.0 / 1.001);
        assert_eq!(standard_rate(12.5), 12.5);
        assert_eq!(standard_rate(29.5), 29.5);
        // a 25-fps phone clip whose low-light stretch runs at 12.5: nominal 25
        let mut steps = vec![0.04; 60];
        steps.extend([0.08; 20]);
        assert_eq!(at(&steps).nominal_fps(), 25.0);
    }

    #[test]
    fn seconds_and_holds_follow_the_frames_times() {
        // 25 fps, then 12.5 fps (frames 10..15 each 80 ms), then 25 fps
        let mut steps = vec![0.04; 10];
        steps.extend([0.08; 5]);
        steps.extend([0.04; 10]);
        let t = at(&steps);
        assert_eq!(t.len(), 26);
        // half way between frames 12 and 13 (0.6 s) rounds up; past the last frame by
        // more than half a step (1.23 s), the count
        for (secs, frame) in [
            (0.0, 0),
            (0.4, 10),
            (0.59, 12),
            (0.6, 13),
            (0.81, 15),
            (1.2, 25),
            (1.23, 26),
            (1.4, 30),
        ] {
            assert_eq!(t.frame_at(secs), frame, "{secs} s");
        }
        // a constant rate: round(seconds × fps)
        let c = at(&[0.04; 50]);
        for s in [0.0, 0.31, 0.52, 0.69, 1.0, 1.99, 2.0, 2.13] {
            assert_eq!(c.frame_at(s), (s * 25.0f64).round() as u64, "{s}");
        }
        // written at 25 fps: the slow frames twice, the rest once
        let h = t.holds(0..26, 25.0, 1000).unwrap();
        assert_eq!(&h[..10], &[1; 10]);
        assert_eq!(&h[10..15], &[2; 5]);
        assert_eq!(&h[15..], &[1; 11]);
        assert_eq!(h.iter().sum::<u32>(), 31, "1.24 s at 25 fps");
        // at 12.5 fps from frame 1: every other fast frame dropped, slow ones once
        let h = t.holds(1..20, 12.5, 1000).unwrap();
        assert_eq!(h.iter().sum::<u32>(), 12, "0.96 s at 12.5 fps");
        assert!(h[10..14].iter().all(|&n| n == 1), "{h:?}");
        // a constant rate at its own rate: every frame once
        assert!(c.holds(5..40, 25.0, 1000).unwrap().iter().all(|&n| n == 1));
        // more frames than allowed (a gap of an hour): refused before counting
        assert_eq!(t.holds(0..26, 25.0, 30), Err(31.0));
        let mut gap = vec![0.04; 10];
        gap.push(3600.0);
        let g = at(&gap);
        assert!(g.holds(0..12, 30.0, 100_000).is_err());
        assert_eq!(g.longest_step(0..12), Some((10, 3600.0)));
    }

    #[test]
    fn bad_times_give_no_timing() {
        assert!(FrameTiming::new(vec![0.0]).is_none());
        assert!(FrameTiming::new(vec![0.0, f64::NAN, 0.1]).is_none());
        // out of order (B-frames in decoding order) is sorted
        let t = FrameTiming::new(vec![0.0, 0.08, 0.04, 0.12]).unwrap();
        assert_eq!(t.times(), &[0.0, 0.04, 0.08, 0.12]);
        // all frames at one time: every step uneven, no rate
        let t = FrameTiming::new(vec![1.0; 5]).unwrap();
        assert_eq!(t.uneven_steps(), vec![0, 1, 2, 3]);
    }
}
