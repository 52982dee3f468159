//! The classic pixel-buffer fire.
//!
//! Source: mcnally-fire-special-fx.txt (Seumas McNally, "Fire Special FX", 1999), the whole
//! article. An 8-bit buffer; every frame, each pixel not within `DONTBURN` ([`ClassicParams::edge`])
//! of an edge becomes `(itself + left + right + below) / 4 − BURNFADE`, clamped at 0; the
//! buffer is shown through a palette ramp from black to a hot colour. The April 13th update
//! adds the "sparklies" and the two source-line modes (mostly random, and smooth 1-D Perlin
//! noise), both implemented here.
//!
//! Two kernels:
//! - [`Kernel::Article`] (default) is the article's loop *exactly*: it updates the buffer in
//!   place, left to right and top to bottom, so `left` is the value already written this
//!   frame while `right` and `below` are still last frame's. That left-to-right dependency
//!   is a serial chain of add/shift/subtract per pixel, so it cannot be vectorised.
//! - [`Kernel::Buffered`] reads all four neighbours from last frame (a double-buffered
//!   box filter). It looks the same to the eye, vectorises (16 pixels per SSE op), and is
//!   the one to use for large buffers.
//!
//! Both run on one thread ([`ClassicFire::step`]) or over row bands with rayon
//! ([`ClassicFire::step_par`]) and give identical bytes either way: a row's new values only
//! depend on its own and the next row's *old* values, so each band keeps a copy of the old
//! row just below it.
//!
//! Seamless loops ([`ClassicFire::new_looping`]): the fire is a contracting recurrence
//! driven by its source line (every frame averages each pixel with its neighbours and
//! fades it, so the buffer forgets its past and becomes a function of the recent source
//! lines). So the loop is made by driving it with a source line and sparklies that repeat
//! every `N` frames and putting the buffer on its periodic orbit under that drive
//! ([`ClassicFire::settle_loop`]). Since no row reads the row above it, the orbit is solved
//! row by row from the source up (module `orbit`): once a row's orbit is known, the row
//! above it alone is stepped until it equals itself a period before, about `N` + 25 steps
//! of one row, where a cold whole buffer takes 240–480 frames to repeat. The `N` states
//! are kept and replayed (loops over 128 MiB keep two rows while solving and are burnt
//! from their phase-0 state: the same bytes). This is chosen over finding and closing the
//! best loop point of an unlooped run because it is exact (frame `N` equals frame 0 byte
//! for byte) and leaves every frame a true frame of the article's simulation: no cut and
//! no blend. The random source becomes a random walk bridged back to its start over the
//! loop and folded into `0..=heat` (folding is what the clamped walk's reflection at the
//! ends does); the Perlin source walks a noise lattice periodic in time.
//!
//! Even steps ([`ClassicFire::even_loop_steps`], module `even`): the preset's puffing and
//! its source's slow heat drift make an exact loop's steps vary by ±30 % (it seems to
//! speed up and slow down, and the wrap is as uneven as any step), so its frames are
//! re-timed at constant speed: frame `k` shows two neighbouring kept states blended at the
//! time where the loop has covered `k/N` of its measured path. Per-pixel buffers (the
//! article's fire) keep their true frames: a blend of fine noise is a double exposure, and
//! the article's steps are within about 1.1–1.2× of the median already.
//!
//! Realism (issue 16 §2; additions beyond the article, off in [`ClassicParams::default`],
//! on in [`ClassicParams::preset`]): the fire has a physical width
//! ([`ClassicParams::diameter`]) and *puffs* like a buoyant diffusion flame, its source heat
//! scaled by a raised-cosine wave at `1.5/√D` Hz ([`ClassicParams::puff`]); and it can be
//! simulated on cells larger than a pixel ([`ClassicParams::cell`]), bilinearly
//! interpolated to the output, since a per-pixel buffer is all fine noise. In a loop the
//! wave makes a whole number of puffs per period, so the inputs still repeat.
//!
//! Buffer convention: row 0 is the top; the fire burns upwards from the source line at the
//! bottom. With [`SourceEdge::Top`] the same simulation runs and the rows are mirrored when a
//! frame is taken, so the fire hangs down from the top.

mod even;
pub mod motion;
mod orbit;

use ignis_core::{GrayFrame, Palette, RgbaFrame, Rng, Size};
use rayon::prelude::*;

/// Errors of the classic fire: only bad parameters.
#[derive(Debug, thiserror::Error)]
pub enum ClassicError {
    #[error("invalid parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    #[error(transparent)]
    Core(#[from] ignis_core::CoreError),
}

fn bad(name: &'static str, reason: impl Into<String>) -> ClassicError {
    ClassicError::BadParameter {
        name,
        reason: reason.into(),
    }
}

/// Which update loop to run; see the module docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// The article's in-place loop (left neighbour already updated this frame).
    #[default]
    Article,
    /// Double-buffered: all neighbours from the previous frame; vectorised.
    Buffered,
}

/// How the source line is driven each frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceMode {
    /// "A mostly random one where each pixel can change up or down by a random amount each
    /// frame": every pixel moves by a uniform step in `−drift..=drift`, clamped to
    /// `0..=heat`.
    Random { drift: u8 },
    /// "A more ordered 1-dimensional Perlin noise function that produces a much smoother
    /// flame": `heat × (0.5 + 0.5·turbulence(x / scale, t · speed))` with 3 octaves.
    Perlin {
        /// Feature size along the line, in pixels (> 0).
        scale: f32,
        /// How fast the pattern evolves, in noise units per frame (≥ 0).
        speed: f32,
    },
}

impl Default for SourceMode {
    fn default() -> Self {
        SourceMode::Random { drift: 48 }
    }
}

/// Where the wall of flame sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceEdge {
    #[default]
    Bottom,
    Top,
}

/// "Sparklies": each frame, one random pixel per line that is darker than `threshold` is
/// brightened by `boost` (never above [`ClassicParams::heat`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Sparkle {
    pub threshold: u8,
    pub boost: u8,
}

/// Cell size of [`ClassicParams::preset`], pixels: the article's per-pixel buffer is all
/// fine noise (a spatial spectrum falling as `k^-2`, where real flames fall about as
/// `k^-3.3`); simulating on 6-pixel cells, interpolated smoothly, gives the larger-scale
/// tongues of a real fire.
pub const PRESET_CELL: u32 = 6;
/// Puffing depth of [`ClassicParams::preset`]: the source heat dips to half at the bottom
/// of each puff, so the flames visibly lengthen and shorten at the law's rate (shallower
/// puffs lose to the random source's slow drift at 30 fps).
pub const PRESET_PUFF: f32 = 0.5;

/// Parameters of the classic fire. Every field has a sensible default: the article's fire
/// exactly ([`ClassicParams::preset`] is the fire Ignis renders by default).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ClassicParams {
    /// Frame size in pixels (the buffer is this in cells, [`ClassicParams::grid`]). Default
    /// 320×200.
    pub size: Size,
    /// BURNFADE: subtracted after averaging, `0..=255`. Larger = shorter flames. Default 1.
    pub fade: u8,
    /// DONTBURN: cells at each edge that never burn, ≥ 1 (the filter reads one pixel to
    /// each side and one below). Default 1.
    pub edge: u32,
    /// Hottest value the source line (and the sparklies) may write, `1..=255`. Default 255.
    pub heat: u8,
    /// Source-line mode. Default random with drift 48.
    pub source: SourceMode,
    /// Bottom (flames rise) or top (flames hang). Default bottom.
    pub source_edge: SourceEdge,
    /// Sparklies; `None` disables them. Default threshold 48, boost 24.
    pub sparkle: Option<Sparkle>,
    /// Update loop. Default [`Kernel::Article`].
    pub kernel: Kernel,
    /// Seed of every random choice.
    pub seed: u64,
    /// Simulation cell size in pixels, ≥ 1: the buffer is `size / cell` (rounded up) and
    /// frames are brought to `size` by bilinear interpolation. 1 is the article's buffer,
    /// pixel for pixel; larger cells give the larger-scale structure of real flames
    /// instead of pixel-level noise. Default 1.
    pub cell: u32,
    /// Puffing (a model addition beyond the article): the source line's heat is scaled by
    /// `1 − puff·(½ − ½·cos 2πft)` with `f = 1.5/√diameter` Hz, the puffing frequency of a
    /// buoyant diffusion flame (Cetegen & Ahmed 1993), so the flames lengthen and shorten
    /// at that rate. `0..=1`; 0 disables it. Default 0.
    pub puff: f32,
    /// The physical width of the fire the buffer shows, metres (> 0): sets the puffing
    /// frequency. Default 1.
    pub diameter: f32,
    /// Frames per second the fire is played at (> 0): one step is one frame, so this turns
    /// the puffing frequency into frames. Default 30.
    pub fps: f32,
}

impl Default for ClassicParams {
    fn default() -> Self {
        ClassicParams {
            size: Size {
                width: 320,
                height: 200,
            },
            fade: 1,
            edge: 1,
            heat: 255,
            source: SourceMode::default(),
            source_edge: SourceEdge::Bottom,
            sparkle: Some(Sparkle {
                threshold: 48,
                boost: 24,
            }),
            kernel: Kernel::Article,
            seed: 0,
            cell: 1,
            puff: 0.0,
            diameter: 1.0,
            fps: 30.0,
        }
    }
}

impl ClassicParams {
    /// Checks every field and their combinations.
    pub fn validate(&self) -> Result<(), ClassicError> {
        Size::new(self.size.width, self.size.height)?;
        if self.cell == 0 {
            return Err(bad(
                "cell",
                "must be at least 1 pixel (1 = the article's buffer)",
            ));
        }
        if !(0.0..=1.0).contains(&self.puff) {
            return Err(bad(
                "puff",
                format!("{}: must be 0..=1 (0 = off)", self.puff),
            ));
        }
        if !(self.diameter > 0.0 && self.diameter.is_finite()) {
            return Err(bad(
                "diameter",
                format!("{}: must be a positive number of metres", self.diameter),
            ));
        }
        if !(self.fps > 0.0 && self.fps.is_finite()) {
            return Err(bad(
                "fps",
                format!("{}: must be a positive frame rate", self.fps),
            ));
        }
        let s = self.grid();
        if self.edge == 0 {
            return Err(bad(
                "edge",
                "must be at least 1 (the filter reads the pixels left, right and below)",
            ));
        }
        let min_side = 2 * self.edge + 2;
        if s.width < min_side || s.height < min_side {
            return Err(bad(
                "size",
                format!(
                    "{} with cells of {} px is a {s} buffer, too small for an edge of {}; \
                     use a buffer of at least {min_side}x{min_side} cells",
                    self.size, self.cell, self.edge
                ),
            ));
        }
        if self.heat == 0 {
            return Err(bad("heat", "must be 1..=255"));
        }
        if let SourceMode::Perlin { scale, speed } = self.source {
            if !(scale > 0.0 && scale.is_finite()) {
                return Err(bad(
                    "source.scale",
                    format!("{scale}: must be a positive number of pixels"),
                ));
            }
            if !(speed >= 0.0 && speed.is_finite()) {
                return Err(bad("source.speed", format!("{speed}: must be ≥ 0")));
            }
        }
        Ok(())
    }

    /// The classic preset (what `ignis classic` renders by default): the article's fire
    /// (random source, sparklies, fade 1) standing for a fire bed [`ClassicParams::diameter`]
    /// = 1 m wide, simulated on cells of [`PRESET_CELL`] pixels and puffing with depth
    /// [`PRESET_PUFF`]. Measured by `ignis bench realism` against the puffing law and
    /// `campfire.mp4`'s spectral slope (crate `benches/README.md`).
    pub fn preset() -> ClassicParams {
        ClassicParams {
            cell: PRESET_CELL,
            puff: PRESET_PUFF,
            diameter: 1.0,
            ..Default::default()
        }
    }

    /// The simulation buffer's size: [`ClassicParams::size`] in cells, rounded up.
    pub fn grid(&self) -> Size {
        let c = self.cell.max(1);
        Size {
            width: self.size.width.div_ceil(c),
            height: self.size.height.div_ceil(c),
        }
    }

    /// The puffing frequency `1.5/√diameter`, Hz.
    pub fn puff_hz(&self) -> f64 {
        1.5 / f64::from(self.diameter).sqrt()
    }
}

/// A running classic fire.
#[derive(Clone, Debug)]
pub struct ClassicFire {
    params: ClassicParams,
    w: usize,
    h: usize,
    buf: Vec<u8>,
    scratch: Vec<u8>,
    rng: Rng,
    /// The source line's own state (random mode drifts it; it is written over the bottom
    /// burnable line after every burn, so the burn never decays it).
    source: Vec<u8>,
    frame: u64,
    noise: Perlin1,
    /// A looping fire's state ([`ClassicFire::new_looping`]).
    looping: Option<Looping>,
    /// Every row above this one is all zero (the black sky above the flames). A zero row
    /// over a zero row stays zero (the edges never burn and sparklies only brighten
    /// burning pixels), so a step only burns from the row just above it: the same bytes
    /// for a fraction of the work, since flames rarely fill the buffer.
    top: usize,
}

/// A kept frame: its topmost non-zero row and the rows from there down.
type Kept = (usize, Vec<u8>);

/// What makes a looping fire's inputs repeat every `period` frames.
#[derive(Clone, Debug)]
struct Looping {
    period: u64,
    /// Random source: the walk's start line and its total over one period (bridged away).
    start: Vec<i64>,
    total: Vec<i64>,
    /// Random source: the walk's sum of steps so far this period.
    walk: Vec<i64>,
    /// Once [`ClassicFire::settle_loop`] has found the loop: its `period` frames, slot `j`
    /// holding the frame whose number is `j` modulo the period, as its topmost non-zero
    /// row and the rows from there down (all above are zero). Stepping then copies the
    /// next one instead of burning (the same bytes: the fire is on its loop).
    replay: Option<Vec<Kept>>,
    /// Perlin source: lattice cells of time per period (octave 0) and noise time per frame.
    cells: i64,
    speed: f32,
    /// Once [`ClassicFire::even_loop_steps`] has re-timed the replayed loop: where each of
    /// its frames sits between two kept states (see [`even`]).
    even: Option<Vec<even::Slot>>,
    /// The last solve's mean steps per row ([`ClassicFire::loop_solve_steps`]).
    solve_steps: Option<f64>,
}

/// The most memory a looping fire keeps to replay its loop; longer or larger loops settle
/// whole periods at a time and are stepped.
const REPLAY_MAX_BYTES: usize = 128 << 20;

/// Most memory a looping fire's solve may hold ([`ClassicFire::new_looping`]): a bound on
/// the loop's length at a size, so a huge `--frames` is refused, not an allocation failure.
pub const MAX_LOOP_BYTES: u64 = 1 << 30;

/// Streams of the looping fire's per-frame random numbers.
const WALK_STREAM: u64 = 0x3a1c_0000_0000;
const SPARK_STREAM: u64 = 0x5a2c_0000_0000;

/// `v` folded into `0..=top` (reflections at both ends), as a clamped random walk that
/// bounces off the ends would be.
fn fold(v: i64, top: i64) -> u8 {
    if top == 0 {
        return 0;
    }
    let m = v.rem_euclid(2 * top);
    (if m > top { 2 * top - m } else { m }) as u8
}

impl ClassicFire {
    /// A cold (all-black) fire. Fails on invalid parameters before allocating.
    pub fn new(params: ClassicParams) -> Result<ClassicFire, ClassicError> {
        params.validate()?;
        let grid = params.grid();
        let (w, h) = (grid.width as usize, grid.height as usize);
        let mut rng = Rng::new(params.seed);
        let noise = Perlin1::new(&mut rng);
        // Start the random source line at random levels: the article's "wall of flame".
        let n = w - 2 * params.edge as usize;
        let heat = params.heat as u32;
        let source = (0..n).map(|_| rng.below(heat + 1) as u8).collect();
        Ok(ClassicFire {
            w,
            h,
            buf: vec![0; w * h],
            scratch: vec![0; w],
            rng,
            source,
            frame: 0,
            noise,
            params,
            looping: None,
            top: 0,
        })
    }

    /// A cold fire whose source line and sparklies repeat every `period` frames (≥ 2), so
    /// that once [`ClassicFire::settle_loop`] has run, frames repeat with that period.
    pub fn new_looping(params: ClassicParams, period: u32) -> Result<ClassicFire, ClassicError> {
        if period < 2 {
            return Err(bad(
                "loop",
                format!("{period} frame(s) cannot loop; ask for at least 2 frames"),
            ));
        }
        let mut fire = ClassicFire::new(params)?;
        // the solve holds, per frame of the loop, two rows of every phase, a sparkle column
        // per row and a few counters (`settle_loop`)
        let (w, h) = (fire.w as u64, fire.h as u64);
        let per_frame = 2 * w
            + 32
            + if fire.params.sparkle.is_some() {
                4 * h
            } else {
                0
            };
        let need = u64::from(period) * per_frame;
        if need > MAX_LOOP_BYTES {
            return Err(bad(
                "loop",
                format!(
                    "a loop of {period} frames of a {}x{}-cell fire would hold {} MiB while \
                     it is solved, over the limit of {} MiB; loop fewer frames (at most {} at \
                     this size) and play the loop over, or turn the loop off",
                    fire.w,
                    fire.h,
                    need >> 20,
                    MAX_LOOP_BYTES >> 20,
                    MAX_LOOP_BYTES / per_frame
                ),
            ));
        }
        let n = fire.source.len();
        let p = &fire.params;
        let start: Vec<i64> = fire.source.iter().map(|&v| v as i64).collect();
        let mut total = vec![0i64; n];
        if let SourceMode::Random { drift } = p.source {
            for k in 0..period as u64 {
                let mut r = Rng::derive(p.seed, WALK_STREAM + k);
                for t in total.iter_mut() {
                    *t += r.range_i32(-(drift as i32), drift as i32) as i64;
                }
            }
        }
        // the Perlin source's time lattice must repeat within the table's 256 cells at
        // every octave (frequency up to 4×), so at most 64 cells of time per loop
        let (cells, speed) = match p.source {
            SourceMode::Perlin { speed, .. } => {
                let c = ((period as f32 * speed).round() as i64).clamp(1, 64);
                (c, c as f32 / period as f32)
            }
            SourceMode::Random { .. } => (1, 0.0),
        };
        fire.looping = Some(Looping {
            period: period as u64,
            start,
            total,
            walk: vec![0; n],
            replay: None,
            cells,
            speed,
            even: None,
            solve_steps: None,
        });
        Ok(fire)
    }

    /// Puts a looping fire on its loop: the buffer's periodic orbit under the repeating
    /// source line and sparklies, solved row by row from the source up (module `orbit`;
    /// each row stepped until it equals itself a period before, at most about
    /// `max_frames` steps), whatever the buffer held before. Leaves the fire on the
    /// loop's phase 0 at the first whole number of periods at least `min_frames` frames
    /// on, and returns the frames it moved on, or `None` if some row did not repeat
    /// within `max_frames` steps (the fire then starts from the solve's last phase-0
    /// state and loops with a seam). Once found, the loop is replayed from memory (up to
    /// 128 MiB of it) instead of burnt again, until [`ClassicFire::set_fade`] changes the
    /// fire; a larger loop is burnt from its phase-0 state, the same bytes. A fire made
    /// with [`ClassicFire::new`] is just stepped `min_frames` frames.
    pub fn settle_loop(&mut self, min_frames: u64, max_frames: u64) -> Option<u64> {
        let Some(period) = self.looping.as_ref().map(|l| l.period) else {
            for _ in 0..min_frames {
                self.step_par();
            }
            return Some(min_frames);
        };
        // at most a whole buffer per frame of the loop is kept
        let most = (period as usize).checked_mul(self.buf.len());
        let keep = most.is_some_and(|b| b <= REPLAY_MAX_BYTES);
        self.solve_loop(period, min_frames, max_frames, keep)
    }

    /// [`ClassicFire::settle_loop`]'s solve, keeping every phase of the orbit to replay it
    /// (`keep`) or only the rows it needs, then setting the buffer to phase 0.
    fn solve_loop(
        &mut self,
        period: u64,
        min_frames: u64,
        max_frames: u64,
        keep: bool,
    ) -> Option<u64> {
        let (w, h, e) = (self.w, self.h, self.params.edge as usize);
        let n = period as usize;
        self.leave_replay();
        // the source row after the frame of phase k holds phase k's source line
        let ys = self.source_row();
        let mut orbit = orbit::Orbit::new(n, w, h, keep, ys);
        for k in 0..period {
            self.drive_source(Some(k));
            let gain = self.puff_gain_at(k);
            let row = orbit.row_mut(((k + 1) % period) as usize, ys);
            put_source(&mut row[e..w - e], &self.source, gain);
        }
        let drive = orbit::Drive::new(&self.params, w, h, n);
        let mut phase0 = vec![0u8; w * h];
        phase0[ys * w..(ys + 1) * w].copy_from_slice(orbit.row(0, ys));
        // each phase's topmost non-zero row so far
        let mut lit = orbit.lit(ys);
        let mut tops: Vec<usize> = lit.iter().map(|&l| if l { ys } else { h }).collect();
        let cap = usize::try_from(max_frames.max(1)).unwrap_or(usize::MAX);
        let (mut periodic, mut steps, mut rows) = (true, 0u64, 0u64);
        let (mut mid, mut new) = (Vec::new(), Vec::new());
        for y in (e..ys).rev() {
            // a row under a row dark at every phase stays dark, and so do all above it
            if !lit.contains(&true) {
                break;
            }
            orbit.add_row(y);
            let s = orbit::solve_row(&mut orbit, y, &drive, cap, (&mut mid, &mut new));
            periodic &= s.is_ok();
            steps += s.unwrap_or_else(|s| s) as u64;
            rows += 1;
            phase0[y * w..(y + 1) * w].copy_from_slice(orbit.row(0, y));
            lit = orbit.lit(y);
            for (t, &l) in tops.iter_mut().zip(&lit) {
                if l {
                    *t = y;
                }
            }
        }
        let start = self.frame;
        let frame = (start + min_frames.max(1)).next_multiple_of(period);
        self.buf = phase0;
        self.top = 0;
        self.update_top();
        self.source
            .copy_from_slice(&self.buf[ys * w + e..ys * w + w - e]);
        self.frame = frame;
        let l = self.looping.as_mut().expect("a looping fire");
        // after a whole period the walk's steps sum to the period's total
        l.walk.clone_from(&l.total);
        l.solve_steps = (rows > 0).then(|| steps as f64 / rows as f64);
        if keep && periodic {
            let ring = orbit.into_kept(&tops);
            l.replay = Some(ring);
        }
        periodic.then_some(frame - start)
    }

    /// The mean steps per row the last [`ClassicFire::settle_loop`] took to find the loop
    /// (comparable to frames of burning the whole buffer); `None` before a solve.
    pub fn loop_solve_steps(&self) -> Option<f64> {
        self.looping.as_ref().and_then(|l| l.solve_steps)
    }

    /// Buffer rows a frame shows, from the top: all of them for cells of 1 pixel; else the
    /// flames above the source line fill the frame: the raw source line (a row of random
    /// hot cells, the brightest and sharpest thing in the buffer) and the dead edge below
    /// it are not shown.
    fn shown_rows(&self) -> usize {
        if self.params.cell == 1 {
            self.h
        } else {
            self.h - self.params.edge as usize - 1
        }
    }

    /// Re-times a found loop so that its frames change by even steps (see [`even`]): frame
    /// `k` shows the kept loop states blended at the time where the loop has covered `k/N`
    /// of its measured path, measured through `palette` over `background` (linear RGB) as
    /// the loop metric sees the written frames. Only for fires simulated on cells over 1
    /// pixel (the preset), whose frames interpolate the cells smoothly, so a blend of
    /// neighbouring states is the state between them; a per-pixel buffer keeps its true
    /// frames (a blend of its fine noise is a double exposure: re-timed, a puffing per-pixel
    /// fire's steps would reach 2.4× the median), and the article's own fire is close to
    /// even already. Returns whether the loop is re-timed: not when no loop is being
    /// replayed ([`ClassicFire::settle_loop`] found none, or it is over 128 MiB), for cells
    /// of 1 pixel, or when no re-timing is more even. The fire's buffer and stepping are
    /// unchanged; [`ClassicFire::frame_bytes`] (and so `gray`, `rgba`) show the re-timed
    /// frames until the replay ends.
    pub fn even_loop_steps(&mut self, palette: &Palette, background: [f32; 3]) -> bool {
        if self.params.cell == 1 {
            return false;
        }
        let (w, shown) = (self.w, self.shown_rows());
        let Some(l) = self.looping.as_mut() else {
            return false;
        };
        let Some(ring) = l.replay.as_ref() else {
            return false;
        };
        let luma = metric_luma(palette, background);
        let size = self.params.size;
        let frame = (size.width as usize, size.height as usize);
        l.even = even::even_slots(ring, (w, shown), frame, &luma);
        l.even.is_some()
    }

    pub fn params(&self) -> &ClassicParams {
        &self.params
    }

    /// The buffer as simulated (source line at the bottom), row-major, `0..=255`.
    pub fn buffer(&self) -> &[u8] {
        &self.buf
    }

    /// Changes BURNFADE while running (e.g. from a UI slider); takes effect next step.
    pub fn set_fade(&mut self, fade: u8) {
        if fade != self.params.fade {
            self.leave_replay();
        }
        self.params.fade = fade;
    }

    /// Stops replaying a found loop (its inputs change): simulation resumes from the
    /// current frame, with the random walk rebuilt for the frame's place in the loop.
    fn leave_replay(&mut self) {
        let Some(l) = self.looping.as_mut() else {
            return;
        };
        l.even = None;
        if l.replay.take().is_none() {
            return;
        }
        l.walk.iter_mut().for_each(|v| *v = 0);
        if let (SourceMode::Random { drift }, true) = (self.params.source, self.frame > 0) {
            let d = drift as i32;
            for k in 0..=(self.frame - 1) % l.period {
                let mut r = Rng::derive(self.params.seed, WALK_STREAM + k);
                for v in l.walk.iter_mut() {
                    *v += r.range_i32(-d, d) as i64;
                }
            }
        }
    }

    /// One frame of a found loop's replay; false when not replaying.
    fn replay_step(&mut self) -> bool {
        let Some(l) = self.looping.as_ref() else {
            return false;
        };
        let Some(ring) = l.replay.as_ref() else {
            return false;
        };
        let (top, rows) = &ring[((self.frame + 1) % l.period) as usize];
        let w = self.w;
        // rows above the current top are zero already
        if self.top < *top {
            self.buf[self.top * w..top * w].fill(0);
        }
        self.buf[top * w..].copy_from_slice(rows);
        self.top = *top;
        let e = self.params.edge as usize;
        let y = self.source_row();
        self.source
            .copy_from_slice(&self.buf[y * w + e..y * w + w - e]);
        self.frame += 1;
        true
    }

    /// Moves `top` to the topmost non-zero row after a step (the sky rises at most one row
    /// a frame, so rows above `top - 1` are still zero).
    fn update_top(&mut self) {
        let w = self.w;
        let mut top = self.top.saturating_sub(1);
        while top < self.h && self.buf[top * w..(top + 1) * w].iter().all(|&v| v == 0) {
            top += 1;
        }
        self.top = top;
    }

    /// Number of frames stepped so far.
    pub fn frame_number(&self) -> u64 {
        self.frame
    }

    /// The furthest bottom burnable line.
    fn source_row(&self) -> usize {
        self.h - 1 - self.params.edge as usize
    }

    /// Advances one frame on the calling thread.
    pub fn step(&mut self) {
        if self.replay_step() {
            return;
        }
        self.burn_to(self.h - self.params.edge as usize, false);
    }

    /// The first row a step must burn: the one just above the topmost row that may be
    /// non-zero, never inside the top edge.
    fn first_burning_row(&self) -> usize {
        let e = self.params.edge as usize;
        self.top.saturating_sub(1).clamp(e, self.h - e)
    }

    /// Advances one frame with the burn spread over rayon's threads in bands of rows.
    /// Gives exactly the bytes [`ClassicFire::step`] gives.
    pub fn step_par(&mut self) {
        if self.replay_step() {
            return;
        }
        self.burn_to(self.h - self.params.edge as usize, true);
    }

    /// One frame: burns the rows from the first burning row down to row `end` (not
    /// included; its old values feed the last burnt row), over rayon's threads when `par`
    /// and there is enough to burn, then the sparklies and the source line. `end` is the
    /// bottom edge.
    fn burn_to(&mut self, end: usize, par: bool) {
        let (w, e) = (self.w, self.params.edge as usize);
        let first = self.first_burning_row().min(end);
        let rows = end - first;
        let (fade, kernel) = (self.params.fade, self.params.kernel);
        if !par || rows * w < PAR_MIN_PIXELS {
            // one thread (also when too little to burn for threads to pay: the usual case
            // under a low flame)
            let below = self.buf[end * w..(end + 1) * w].to_vec();
            let band = &mut self.buf[first * w..end * w];
            burn_band(band, w, e, &below, fade, kernel, &mut self.scratch);
            return self.after_burn();
        }
        let threads = rayon::current_num_threads().max(1);
        // bands of at least 16 rows, about four per thread for load balance
        let band = rows.div_ceil(threads * 4).max(16);
        let region = &mut self.buf[first * w..(end + 1) * w];
        // the old row just below each band, copied before any band changes it
        let belows: Vec<Vec<u8>> = (0..rows.div_ceil(band))
            .map(|b| {
                let r = ((b + 1) * band).min(rows);
                region[r * w..(r + 1) * w].to_vec()
            })
            .collect();
        let burnable = &mut region[..rows * w];
        burnable
            .par_chunks_mut(band * w)
            .zip(belows.par_iter())
            .for_each_init(
                || vec![0u8; w],
                |scratch, (chunk, below)| burn_band(chunk, w, e, below, fade, kernel, scratch),
            );
        self.after_burn();
    }

    /// Sparklies and the source line, after the burn.
    fn after_burn(&mut self) {
        let (w, e) = (self.w, self.params.edge as usize);
        let heat = self.params.heat;
        let k = self.looping.as_ref().map(|l| self.frame % l.period);
        if let Some(sp) = self.params.sparkle {
            // a loop's sparklies repeat with it: their random numbers come from the
            // frame's place in the loop
            let mut looped_rng = k.map(|k| Rng::derive(self.params.seed, SPARK_STREAM + k));
            for y in e..self.h - e {
                let rng = looped_rng.as_mut().unwrap_or(&mut self.rng);
                let x = e + rng.below((w - 2 * e) as u32) as usize;
                let p = &mut self.buf[y * w + x];
                *p = sparkled(*p, sp, heat);
            }
        }
        self.drive_source(k);
        let y = self.source_row();
        let gain = self.puff_gain();
        put_source(&mut self.buf[y * w + e..y * w + w - e], &self.source, gain);
        self.update_top();
        self.frame += 1;
    }

    /// Moves the source line on one frame (`k`: the frame's place in a loop, `None` when
    /// not looping).
    fn drive_source(&mut self, k: Option<u64>) {
        let e = self.params.edge as usize;
        let heat = self.params.heat;
        let line = &mut self.source;
        // the Perlin feature size is in pixels; the line is in cells
        let cell = self.params.cell as f32;
        match (self.params.source, self.looping.as_mut(), k) {
            (SourceMode::Random { drift }, Some(l), Some(k)) => {
                // the walk bridged back to its start over the period: after step `j`
                // (1..=N) of the period it is `start + C(j) − j·total/N`, exactly `start`
                // again at `j = N`
                if k == 0 {
                    l.walk.iter_mut().for_each(|v| *v = 0);
                }
                let d = drift as i32;
                let mut r = Rng::derive(self.params.seed, WALK_STREAM + k);
                let (j, n) = (k as i64 + 1, l.period as i64);
                for (i, p) in line.iter_mut().enumerate() {
                    l.walk[i] += r.range_i32(-d, d) as i64;
                    let v = l.start[i] * n + l.walk[i] * n - j * l.total[i];
                    *p = fold(v.div_euclid(n), heat as i64);
                }
            }
            (SourceMode::Perlin { scale, .. }, Some(l), Some(k)) => {
                let t = k as f32 * l.speed;
                for (i, p) in line.iter_mut().enumerate() {
                    let x = (i + e) as f32 * cell / scale;
                    let n = self.noise.turbulence_periodic(x, t, Some(l.cells));
                    *p = ((0.5 + 0.5 * n).clamp(0.0, 1.0) * heat as f32).round() as u8;
                }
            }
            (SourceMode::Random { drift }, _, _) => {
                let d = drift as i32;
                for p in line.iter_mut() {
                    let v = *p as i32 + self.rng.range_i32(-d, d);
                    *p = v.clamp(0, heat as i32) as u8;
                }
            }
            (SourceMode::Perlin { scale, speed }, _, _) => {
                let t = self.frame as f32 * speed;
                for (i, p) in line.iter_mut().enumerate() {
                    let x = (i + e) as f32 * cell / scale;
                    let n = self.noise.turbulence(x, t);
                    *p = ((0.5 + 0.5 * n).clamp(0.0, 1.0) * heat as f32).round() as u8;
                }
            }
        }
    }

    /// The puffing wave's gain on the source line this frame, in 256ths (`None`: off). A
    /// loop puffs a whole number of times over its period (the nearest to the law's
    /// frequency; none when the loop is shorter than half a puff).
    fn puff_gain(&self) -> Option<u32> {
        self.puff_gain_at(self.frame)
    }

    /// [`ClassicFire::puff_gain`] for frame number `frame`.
    fn puff_gain_at(&self, frame: u64) -> Option<u32> {
        let p = &self.params;
        if p.puff <= 0.0 {
            return None;
        }
        let per_frame = p.puff_hz() / f64::from(p.fps);
        let phase = match &self.looping {
            Some(l) => {
                let cycles = (l.period as f64 * per_frame).round();
                if cycles == 0.0 {
                    return None;
                }
                (frame % l.period) as f64 * cycles / l.period as f64
            }
            None => frame as f64 * per_frame,
        };
        let dip = 0.5 - 0.5 * (std::f64::consts::TAU * phase.fract()).cos();
        Some(((1.0 - f64::from(p.puff) * dip) * 256.0).round() as u32)
    }

    /// The current frame as linear intensities `0..=1` (value / 255) at
    /// [`ClassicParams::size`]: the buffer's bytes as [`ClassicFire::frame_bytes`] gives them.
    pub fn gray(&self) -> GrayFrame {
        let data = self
            .frame_bytes()
            .iter()
            .map(|&v| v as f32 / 255.0)
            .collect();
        GrayFrame::from_vec(self.params.size, data).expect("buffer matches size")
    }

    /// The current frame through `palette`, indexing the table by the byte value exactly
    /// as the article's 256-entry palette does.
    pub fn rgba(&self, palette: &Palette) -> RgbaFrame {
        palette
            .apply_indexed(self.params.size, &self.frame_bytes())
            .expect("buffer matches size")
    }

    /// The frame's bytes at [`ClassicParams::size`], row 0 at the top: the buffer itself
    /// for cells of 1 pixel, else bilinearly interpolated between cell centres (integer
    /// arithmetic, so the same bytes everywhere); mirrored for a top source edge.
    ///
    /// A loop re-timed by [`ClassicFire::even_loop_steps`] shows, in place of the buffer,
    /// the blend of two kept loop states its frame number stands for.
    pub fn frame_bytes(&self) -> Vec<u8> {
        let size = self.params.size;
        let (ow, oh) = (size.width as usize, size.height as usize);
        let evened = self.looping.as_ref().and_then(|l| {
            let (ring, slots) = (l.replay.as_ref()?, l.even.as_ref()?);
            let slot = slots[(self.frame % l.period) as usize];
            Some(even::blend(ring, slot, self.w, self.h))
        });
        let buf = evened.as_deref().unwrap_or(&self.buf);
        let mut out = if self.params.cell == 1 {
            buf.to_vec()
        } else {
            let shown = self.shown_rows();
            upsample(&buf[..shown * self.w], self.w, shown, ow, oh)
        };
        if self.params.source_edge == SourceEdge::Top {
            out = out.chunks_exact(ow).rev().flatten().copied().collect();
        }
        out
    }
}

/// A pixel after the sparklies: "sparklies in the darker flame": only pixels already
/// burning (> 0) and darker than the threshold are brightened, so the black sky above the
/// flames stays black.
#[inline]
fn sparkled(p: u8, sp: Sparkle, heat: u8) -> u8 {
    if p > 0 && p < sp.threshold {
        p.saturating_add(sp.boost).min(heat)
    } else {
        p
    }
}

/// Writes the source line into `row` (the burnable part of the source row), scaled by the
/// puffing gain in 256ths.
fn put_source(row: &mut [u8], source: &[u8], gain: Option<u32>) {
    match gain {
        None => row.copy_from_slice(source),
        Some(g) => {
            for (o, &v) in row.iter_mut().zip(source) {
                *o = ((v as u32 * g + 128) >> 8) as u8;
            }
        }
    }
}

/// The loop metric's grey (`ignis_core::loopq`) of each palette entry shown over
/// `background`: the metric frame of a 16×16 frame of the 256 entries (a frame that
/// narrow is measured at its own size, pixel for pixel).
fn metric_luma(palette: &Palette, background: [f32; 3]) -> [f32; 256] {
    let side = Size {
        width: 16,
        height: 16,
    };
    let all: Vec<u8> = (0..=255).collect();
    let frame = palette
        .apply_indexed(side, &all)
        .expect("256 entries for 16x16 pixels");
    let metric = ignis_core::loopq::metric_frame_rgba(&frame, background);
    std::array::from_fn(|v| metric.data()[v])
}

/// For each of `n` output samples spread evenly over `len` cells: the two cells around the
/// sample's centre and the second one's weight in 256ths.
fn taps(n: usize, len: usize) -> Vec<(usize, usize, u32)> {
    (0..n)
        .map(|x| {
            // centre of output pixel x in cell units, minus a half: ((2x + 1)·len − n) / 2n
            let num = (2 * x as i64 + 1) * len as i64 - n as i64;
            let den = 2 * n as i64;
            let i0 = num.div_euclid(den);
            let frac = num.rem_euclid(den);
            let wt = ((frac * 256 + n as i64) / den) as u32;
            let c = |i: i64| i.clamp(0, len as i64 - 1) as usize;
            (c(i0), c(i0 + 1), wt)
        })
        .collect()
}

/// `src` (`w`×`h` cells) bilinearly interpolated to `ow`×`oh` pixels.
fn upsample(src: &[u8], w: usize, h: usize, ow: usize, oh: usize) -> Vec<u8> {
    let (tx, ty) = (taps(ow, w), taps(oh, h));
    // each cell row interpolated across, in 256ths
    let wide: Vec<u16> = src
        .chunks_exact(w)
        .flat_map(|row| {
            tx.iter()
                .map(move |&(a, b, t)| (row[a] as u32 * (256 - t) + row[b] as u32 * t) as u16)
        })
        .collect();
    let mut out = Vec::with_capacity(ow * oh);
    for &(a, b, t) in &ty {
        let (ra, rb) = (&wide[a * ow..(a + 1) * ow], &wide[b * ow..(b + 1) * ow]);
        out.extend(
            ra.iter()
                .zip(rb)
                .map(|(&p, &q)| ((p as u32 * (256 - t) + q as u32 * t + 32768) >> 16) as u8),
        );
    }
    out
}

/// Burns the rows of `band` (a whole number of rows of width `w`), top to bottom; `below` is
/// the old row under the band's last row. Each row reads its own old values and the old
/// values of the row below it, so bands are independent.
fn burn_band(
    band: &mut [u8],
    w: usize,
    e: usize,
    below: &[u8],
    fade: u8,
    kernel: Kernel,
    scratch: &mut [u8],
) {
    let rows = band.len() / w;
    let mut r = 0;
    if kernel == Kernel::Article {
        // Groups of ARTICLE_ROWS rows interleaved column by column: each row is a serial
        // chain, but different rows' chains are independent, so the CPU overlaps them.
        while r + ARTICLE_ROWS <= rows {
            let (head, rest) = band.split_at_mut((r + ARTICLE_ROWS) * w);
            let under: &[u8] = if r + ARTICLE_ROWS < rows {
                &rest[..w]
            } else {
                below
            };
            let mut it = head[r * w..].chunks_exact_mut(w);
            let group: [&mut [u8]; ARTICLE_ROWS] = std::array::from_fn(|_| it.next().expect("row"));
            burn_rows_article(group, under, e, fade);
            r += ARTICLE_ROWS;
        }
    }
    while r < rows {
        let (cur_part, rest) = band.split_at_mut((r + 1) * w);
        let cur = &mut cur_part[r * w..];
        let under: &[u8] = if r + 1 < rows { &rest[..w] } else { below };
        match kernel {
            Kernel::Article => burn_rows_article([cur], under, e, fade),
            Kernel::Buffered => {
                scratch.copy_from_slice(cur);
                burn_row_buffered(cur, scratch, under, e, fade);
            }
        }
        r += 1;
    }
}

/// Below this many pixels to burn, [`ClassicFire::step_par`] burns on the calling thread:
/// handing out bands costs more than it saves.
const PAR_MIN_PIXELS: usize = 32 * 1024;

/// Rows the article kernel interleaves.
const ARTICLE_ROWS: usize = 8;

/// The article's inner loop over `N` consecutive rows at once, exactly as the C code: in
/// place, left to right, `left` being this frame's value and `right`/`below` last frame's.
/// Row `k` reads row `k + 1` at column `x` before row `k + 1`'s column `x` is updated, and
/// the last row reads `under`, so the result is the same as running the rows one by one.
///
/// `floor((a + b + c + d) / 4) − fade`, clamped at 0, is computed as
/// `max((a + b + c + d − 4·fade) >> 2, 0)` with an arithmetic shift: the same integer.
#[inline]
fn burn_rows_article<const N: usize>(mut rows: [&mut [u8]; N], under: &[u8], e: usize, fade: u8) {
    let w = under.len();
    for r in rows.iter() {
        assert_eq!(r.len(), w);
    }
    let f4 = 4 * fade as i32;
    let mut left: [i32; N] = std::array::from_fn(|k| rows[k][e - 1] as i32);
    for x in e..w - e {
        for k in 0..N {
            let below = if k + 1 < N { rows[k + 1][x] } else { under[x] } as i32;
            let row = &mut rows[k];
            let s = left[k] + row[x] as i32 + row[x + 1] as i32 + below - f4;
            let v = (s >> 2).max(0);
            row[x] = v as u8;
            left[k] = v;
        }
    }
}

/// One row of the double-buffered kernel: `old` is the row before this frame.
#[inline]
fn burn_row_buffered(cur: &mut [u8], old: &[u8], under: &[u8], e: usize, fade: u8) {
    let w = cur.len();
    let n = w - 2 * e;
    let (l, m, r, u) = (
        &old[e - 1..e - 1 + n],
        &old[e..e + n],
        &old[e + 1..e + 1 + n],
        &under[e..e + n],
    );
    let out = &mut cur[e..e + n];
    let fade = fade as u16;
    for i in 0..n {
        let s = (l[i] as u16 + m[i] as u16 + r[i] as u16 + u[i] as u16) >> 2;
        out[i] = s.saturating_sub(fade) as u8;
    }
}

/// 1-D gradient noise (Perlin) with a time dimension, for the smooth source line.
///
/// Two-dimensional in `(x, t)` so the line evolves smoothly between frames; gradients from
/// a seeded permutation table, quintic fade as in Perlin's Improved Noise.
#[derive(Clone, Debug)]
struct Perlin1 {
    perm: [u8; 512],
}

impl Perlin1 {
    fn new(rng: &mut Rng) -> Perlin1 {
        let mut p: Vec<u8> = (0..=255u8).collect();
        for i in (1..256).rev() {
            let j = rng.below(i as u32 + 1) as usize;
            p.swap(i, j);
        }
        let mut perm = [0u8; 512];
        for i in 0..512 {
            perm[i] = p[i & 255];
        }
        Perlin1 { perm }
    }

    fn grad(h: u8, x: f32, y: f32) -> f32 {
        match h & 7 {
            0 => x + y,
            1 => x - y,
            2 => -x + y,
            3 => -x - y,
            4 => x,
            5 => -x,
            6 => y,
            _ => -y,
        }
    }

    /// The noise at `(x, y)`; with `period = Some(p)` (1..=256) its lattice repeats every
    /// `p` cells in `y`, so the noise does too.
    fn noise(&self, x: f32, y: f32, period: Option<i64>) -> f32 {
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (xf, yf) = (x.floor(), y.floor());
        let xi = (xf as i64 & 255) as usize;
        let (yi, yj) = match period {
            None => ((yf as i64 & 255) as usize, (yf as i64 & 255) as usize + 1),
            Some(p) => (
                (yf as i64).rem_euclid(p) as usize,
                (yf as i64 + 1).rem_euclid(p) as usize,
            ),
        };
        let (x, y) = (x - xf, y - yf);
        let (u, v) = (fade(x), fade(y));
        let p = &self.perm;
        let (a, b) = (p[xi] as usize, p[xi + 1] as usize);
        let lerp = |t: f32, a: f32, b: f32| a + t * (b - a);
        lerp(
            v,
            lerp(
                u,
                Self::grad(p[a + yi], x, y),
                Self::grad(p[b + yi], x - 1.0, y),
            ),
            lerp(
                u,
                Self::grad(p[a + yj], x, y - 1.0),
                Self::grad(p[b + yj], x - 1.0, y - 1.0),
            ),
        )
    }

    /// Three octaves (gain 0.5, lacunarity 2), roughly in `−1..=1`.
    fn turbulence(&self, x: f32, t: f32) -> f32 {
        self.turbulence_periodic(x, t, None)
    }

    /// [`Perlin1::turbulence`], periodic in `t` with `cells` (1..=64) when given: octave
    /// `i` samples `t · 2^i` on a lattice of `cells · 2^i` cells.
    fn turbulence_periodic(&self, x: f32, t: f32, cells: Option<i64>) -> f32 {
        let (mut sum, mut amp, mut f) = (0.0, 1.0, 1.0);
        for o in 0..3 {
            sum += amp * self.noise(x * f, t * f, cells.map(|c| c << o));
            amp *= 0.5;
            f *= 2.0;
        }
        sum / 1.75 * 1.4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(w: u32, h: u32) -> ClassicParams {
        ClassicParams {
            size: Size::new(w, h).unwrap(),
            seed: 3,
            ..Default::default()
        }
    }

    #[test]
    fn article_row_matches_the_c_code() {
        // Direct transcription of the article's loop on a 5x3 buffer, DONTBURN = 1.
        let (w, h, e, fade) = (5usize, 3usize, 1usize, 1i32);
        let init: Vec<u8> = vec![9, 9, 9, 9, 9, 40, 80, 120, 160, 200, 255, 10, 20, 30, 0];
        let mut c = init.clone();
        for y in e..h - e {
            for x in e..w - e {
                let p = ((c[y * w + x] as i32
                    + c[y * w + x - 1] as i32
                    + c[y * w + x + 1] as i32
                    + c[(y + 1) * w + x] as i32)
                    >> 2)
                    - fade;
                c[y * w + x] = if p < 0 { 0 } else { p as u8 };
            }
        }
        let mut ours = init.clone();
        let below = ours[2 * w..3 * w].to_vec();
        burn_band(
            &mut ours[w..2 * w],
            w,
            e,
            &below,
            fade as u8,
            Kernel::Article,
            &mut vec![0; w],
        );
        assert_eq!(ours, c);
    }

    #[test]
    fn rejects_bad_parameters() {
        assert!(ClassicFire::new(ClassicParams {
            edge: 0,
            ..params(32, 32)
        })
        .is_err());
        assert!(ClassicFire::new(ClassicParams {
            edge: 20,
            ..params(32, 32)
        })
        .is_err());
        assert!(ClassicFire::new(ClassicParams {
            heat: 0,
            ..params(32, 32)
        })
        .is_err());
        let p = ClassicParams {
            source: SourceMode::Perlin {
                scale: 0.0,
                speed: 1.0,
            },
            ..params(32, 32)
        };
        assert!(ClassicFire::new(p).is_err());
    }

    #[test]
    fn perlin_source_is_smooth() {
        let p = ClassicParams {
            source: SourceMode::Perlin {
                scale: 24.0,
                speed: 0.05,
            },
            ..params(200, 20)
        };
        let mut f = ClassicFire::new(p).unwrap();
        f.step();
        let y = f.source_row();
        let line = &f.buffer()[y * 200 + 1..y * 200 + 199];
        let max_jump = line
            .windows(2)
            .map(|w| (w[0] as i32 - w[1] as i32).abs())
            .max()
            .unwrap();
        assert!(max_jump <= 40, "smooth source line, max jump {max_jump}");
        let spread = *line.iter().max().unwrap() as i32 - *line.iter().min().unwrap() as i32;
        assert!(spread > 40, "it varies along the line, spread {spread}");
    }

    /// A looping fire settles into an exact loop: after `settle_loop`, stepping `N` more
    /// frames gives the same buffer, for both source modes, sparklies on.
    #[test]
    fn looping_fire_repeats_exactly() {
        for source in [
            SourceMode::Random { drift: 48 },
            SourceMode::Perlin {
                scale: 12.0,
                speed: 0.08,
            },
        ] {
            for n in [3u32, 17] {
                let p = ClassicParams {
                    source,
                    ..params(48, 36)
                };
                let mut f = ClassicFire::new_looping(p, n).unwrap();
                let settled = f.settle_loop(60, 4000);
                assert!(settled.is_some(), "{source:?} N={n} never repeats");
                // each row is periodic within a period and a few dozen steps (a cold
                // buffer needs many periods)
                let steps = f.loop_solve_steps().unwrap();
                assert!(
                    steps >= n as f64 && steps <= n as f64 + 64.0,
                    "{source:?} N={n}: {steps} steps a row"
                );
                let first = f.buffer().to_vec();
                assert!(first.iter().any(|&v| v > 0), "burning");
                let mut seen_change = false;
                for _ in 0..n {
                    f.step_par();
                    seen_change |= f.buffer() != &first[..];
                }
                assert!(seen_change, "{source:?} N={n}: the fire moves");
                assert_eq!(f.buffer(), &first[..], "{source:?} N={n}");
            }
        }
        assert!(ClassicFire::new_looping(params(32, 32), 1).is_err());
    }

    /// A loop whose solve would hold more than [`MAX_LOOP_BYTES`] is refused with the
    /// longest that fits, before anything is allocated; that one is accepted.
    #[test]
    fn a_loop_too_long_to_solve_is_refused() {
        let p = params(32, 24);
        let Err(e) = ClassicFire::new_looping(p.clone(), u32::MAX) else {
            panic!("a loop of u32::MAX frames was accepted");
        };
        let e = e.to_string();
        assert!(e.contains("turn the loop off"), "{e}");
        let most: u32 = e
            .split("(at most ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse().ok())
            .expect("the longest loop named");
        assert!(ClassicFire::new_looping(p.clone(), most + 1).is_err());
        assert!(ClassicFire::new_looping(p, most).is_ok());
    }

    /// Skipping the black sky gives the bytes of burning every row: each step is checked
    /// against a copy told that no row is known to be zero, while the flames grow, die
    /// down under a large fade (the sky falls) and grow back, for both kernels, one
    /// thread and rayon, plain and looping.
    #[test]
    fn sky_skip_gives_the_bytes_of_a_full_burn() {
        for kernel in [Kernel::Article, Kernel::Buffered] {
            for looping in [false, true] {
                let p = ClassicParams {
                    kernel,
                    ..params(40, 48)
                };
                let mut f = if looping {
                    ClassicFire::new_looping(p, 7).unwrap()
                } else {
                    ClassicFire::new(p).unwrap()
                };
                let mut skipped = 0;
                for i in 0..90 {
                    f.set_fade(match i {
                        0..=29 => 0,
                        30..=49 => 40,
                        _ => 1,
                    });
                    let mut full = f.clone();
                    full.top = 0;
                    skipped += f.first_burning_row() - 1;
                    if i % 2 == 0 {
                        f.step();
                        full.step();
                    } else {
                        f.step_par();
                        full.step_par();
                    }
                    assert_eq!(
                        f.buffer(),
                        full.buffer(),
                        "{kernel:?} looping={looping} i={i}"
                    );
                    assert!(f.buffer()[..f.top * 40].iter().all(|&v| v == 0));
                }
                assert!(skipped > 0, "some sky was skipped");
            }
        }
    }

    /// The banded burn (enough pixels under the sky for threads) gives the one-thread
    /// bytes on a 3-thread pool, for both kernels, while the sky falls under a large fade
    /// and the burn drops to the calling thread.
    #[test]
    fn banded_and_small_burns_match_one_thread() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        for kernel in [Kernel::Article, Kernel::Buffered] {
            let p = ClassicParams {
                kernel,
                fade: 0,
                ..params(220, 160)
            };
            let (mut one, mut par) = (
                ClassicFire::new(p.clone()).unwrap(),
                ClassicFire::new(p).unwrap(),
            );
            let (mut banded, mut small) = (0, 0);
            for i in 0..40 {
                let fade = if i < 25 { 0 } else { 60 };
                one.set_fade(fade);
                par.set_fade(fade);
                let rows = par.h - par.params.edge as usize - par.first_burning_row();
                if rows * par.w >= PAR_MIN_PIXELS {
                    banded += 1;
                } else {
                    small += 1;
                }
                one.step();
                pool.install(|| par.step_par());
                assert_eq!(one.buffer(), par.buffer(), "{kernel:?} frame {i}");
            }
            assert!(
                banded > 0 && small > 0,
                "{kernel:?}: {banded} banded, {small} small"
            );
        }
    }

    /// The solved loop replayed from memory gives the bytes of burning on from its phase-0
    /// state (the solve that keeps only the rows it needs, as for loops over 128 MiB), and
    /// burning returns to phase 0 after a period: the orbit is a true orbit of the
    /// simulation. Also when the replay is left mid-loop (a fade change) and the
    /// simulation resumes; and with too short a limit both give up on the same buffer.
    #[test]
    fn replayed_loop_matches_the_simulated_one() {
        for source in [
            SourceMode::Random { drift: 48 },
            SourceMode::Perlin {
                scale: 12.0,
                speed: 0.08,
            },
        ] {
            for (n, min) in [(5u32, 0u64), (17, 60), (40, 10)] {
                // the double-buffered kernel's rows are solved by their own step
                let kernel = if n == 17 {
                    Kernel::Buffered
                } else {
                    Kernel::Article
                };
                let p = ClassicParams {
                    source,
                    kernel,
                    ..params(44, 40)
                };
                let mut replayed = ClassicFire::new_looping(p.clone(), n).unwrap();
                let mut simulated = replayed.clone();
                assert!(replayed.settle_loop(min, 4000).is_some());
                assert!(replayed.looping.as_ref().unwrap().replay.is_some());
                assert!(simulated.solve_loop(n as u64, min, 4000, false).is_some());
                assert!(simulated.looping.as_ref().unwrap().replay.is_none());
                assert_eq!(replayed.buffer(), simulated.buffer(), "{source:?} N={n}");
                assert_eq!(replayed.frame_number(), simulated.frame_number());
                assert_eq!(replayed.frame_number() % n as u64, 0);
                assert!(replayed.frame_number() >= min.max(1));
                let phase0 = simulated.buffer().to_vec();
                assert!(phase0.iter().any(|&v| v > 0), "burning");
                let mut burnt = simulated.clone();
                let mut moved = false;
                for _ in 0..n {
                    burnt.step();
                    moved |= burnt.buffer() != &phase0[..];
                }
                assert!(moved, "{source:?} N={n}: the fire moves");
                assert_eq!(
                    burnt.buffer(),
                    &phase0[..],
                    "{source:?} N={n}: burnt a period"
                );
                for i in 0..2 * n + 3 {
                    if i == n + 2 {
                        // leave the replay mid-loop on a copy of the replayed fire
                        let mut left = replayed.clone();
                        left.leave_replay();
                        assert!(left.looping.as_ref().unwrap().replay.is_none());
                        for j in 0..n + 4 {
                            left.step();
                            replayed.step();
                            assert_eq!(
                                left.buffer(),
                                replayed.buffer(),
                                "{source:?} N={n} left {j}"
                            );
                        }
                    }
                    replayed.step_par();
                    simulated.step_par();
                }
                let (mut a, mut b) = (replayed.clone(), simulated.clone());
                while a.frame_number() % n as u64 != 0 {
                    a.step();
                }
                while b.frame_number() % n as u64 != 0 {
                    b.step();
                }
                assert_eq!(a.buffer(), b.buffer(), "{source:?} N={n} after the replay");
                if n as usize <= 8 {
                    // a row checks itself every 8 steps: a shorter loop may repeat at once
                    continue;
                }
                let (mut short_a, mut short_b) = (
                    ClassicFire::new_looping(p.clone(), n).unwrap(),
                    ClassicFire::new_looping(p, n).unwrap(),
                );
                assert!(short_a.settle_loop(0, 1).is_none());
                assert!(short_a.looping.as_ref().unwrap().replay.is_none());
                assert!(short_b.solve_loop(n as u64, 0, 1, false).is_none());
                assert_eq!(short_a.buffer(), short_b.buffer());
                assert_eq!(short_a.frame_number(), short_b.frame_number());
            }
        }
    }

    /// The preset's additions keep the loop exact: cells of 3 px with puffing at 1.5 Hz and
    /// 30 fps, over loops of 3 frames (too short for a puff: off) and 40 (three puffs), both
    /// sources; the written frames (interpolated) repeat too.
    #[test]
    fn puffing_coarse_fire_loops_exactly() {
        for source in [
            SourceMode::Random { drift: 48 },
            SourceMode::Perlin {
                scale: 36.0,
                speed: 0.08,
            },
        ] {
            for n in [3u32, 40] {
                let p = ClassicParams {
                    source,
                    cell: 3,
                    puff: 0.8,
                    ..params(144, 108)
                };
                let mut f = ClassicFire::new_looping(p.clone(), n).unwrap();
                assert!(f.settle_loop(60, 8000).is_some(), "{source:?} N={n}");
                let first = f.frame_bytes();
                assert_eq!(first.len(), 144 * 108);
                assert!(first.iter().any(|&v| v > 0), "burning");
                for _ in 0..n {
                    f.step_par();
                }
                assert_eq!(f.frame_bytes(), first, "{source:?} N={n}");
                // burnt, not replayed, the solved state comes back after a period too
                let mut burnt = ClassicFire::new_looping(p, n).unwrap();
                assert!(burnt.solve_loop(n as u64, 60, 8000, false).is_some());
                assert_eq!(burnt.frame_bytes(), first, "{source:?} N={n} phase 0");
                for _ in 0..n {
                    burnt.step_par();
                }
                assert_eq!(burnt.frame_bytes(), first, "{source:?} N={n} burnt");
            }
        }
    }

    /// The puffing wave's gain: full heat at the top of a puff, `1 − puff` at the bottom,
    /// half a period (20 frames at 1.5 Hz and 60 fps) apart; off at depth 0.
    #[test]
    fn puff_gain_follows_the_law() {
        let p = ClassicParams {
            puff: 0.8,
            fps: 60.0,
            ..params(32, 32)
        };
        let mut f = ClassicFire::new(p.clone()).unwrap();
        assert_eq!(f.puff_gain(), Some(256));
        for _ in 0..20 {
            f.step();
        }
        assert_eq!(f.puff_gain(), Some(51)); // round(0.2 · 256)
        for _ in 0..20 {
            f.step();
        }
        assert_eq!(f.puff_gain(), Some(256));
        let off = ClassicFire::new(ClassicParams { puff: 0.0, ..p }).unwrap();
        assert_eq!(off.puff_gain(), None);
    }

    /// Bilinear interpolation between cell centres: a constant stays constant, a step
    /// between two cells becomes a symmetric ramp clamped at the outer half-cells, and
    /// cells of 1 px are the buffer itself.
    #[test]
    fn upsample_interpolates_between_cell_centres() {
        assert_eq!(upsample(&[77; 6], 3, 2, 12, 8), vec![77; 96]);
        let ramp = upsample(&[0, 255], 2, 1, 8, 1);
        assert_eq!(&ramp[..2], &[0, 0]);
        assert_eq!(&ramp[6..], &[255, 255]);
        assert!(ramp.windows(2).all(|w| w[0] <= w[1]), "{ramp:?}");
        for i in 0..8 {
            assert!(
                (ramp[i] as i32 + ramp[7 - i] as i32 - 255).abs() <= 1,
                "{ramp:?}"
            );
        }
        let taps1 = taps(5, 5);
        assert!(taps1
            .iter()
            .enumerate()
            .all(|(i, &(a, _, t))| a == i && t == 0));
        let f = ClassicFire::new(ClassicParams {
            cell: 4,
            ..params(50, 30)
        })
        .unwrap();
        assert_eq!(f.params().grid(), Size::new(13, 8).unwrap());
        assert!(ClassicFire::new(ClassicParams {
            cell: 0,
            ..params(50, 30)
        })
        .is_err());
        // 12x12 px in cells of 4 is 3x3: too small for an edge of 1
        let e = ClassicFire::new(ClassicParams {
            cell: 4,
            ..params(12, 12)
        })
        .unwrap_err();
        assert!(e.to_string().contains("cells of 4 px"), "{e}");
    }

    /// Re-timing needs a replayed loop of a fire on cells over 1 pixel; changing the fade
    /// (which leaves the replay) drops it, and frames show the simulated buffer again.
    #[test]
    fn even_steps_only_while_replaying_the_loop() {
        let palette = Palette::preset("classic").unwrap();
        let preset = ClassicParams {
            cell: 3,
            ..ClassicParams::preset()
        };
        let p = ClassicParams {
            size: Size::new(60, 48).unwrap(),
            ..preset
        };
        let mut plain = ClassicFire::new(p.clone()).unwrap();
        plain.settle_loop(30, 100);
        assert!(!plain.even_loop_steps(&palette, [0.0; 3]));
        // per-pixel buffers keep their true frames, puffing or not
        for puff in [0.0, 0.5] {
            let mut fine = ClassicFire::new_looping(
                ClassicParams {
                    puff,
                    ..params(60, 48)
                },
                12,
            )
            .unwrap();
            fine.settle_loop(60, 4000).unwrap();
            assert!(!fine.even_loop_steps(&palette, [0.0; 3]), "puff {puff}");
        }
        let mut f = ClassicFire::new_looping(p, 16).unwrap();
        assert!(!f.even_loop_steps(&palette, [0.0; 3]), "not settled yet");
        f.settle_loop(60, 4000).unwrap();
        assert!(f.even_loop_steps(&palette, [0.0; 3]));
        f.set_fade(2);
        assert!(f.looping.as_ref().unwrap().even.is_none());
        f.step();
        let shown = f.h - 2;
        let want = upsample(&f.buf[..shown * f.w], f.w, shown, 60, 48);
        assert_eq!(f.frame_bytes(), want);
    }

    #[test]
    fn fold_reflects_at_both_ends() {
        assert_eq!(fold(-3, 10), 3);
        assert_eq!(fold(12, 10), 8);
        assert_eq!(fold(25, 10), 5);
        assert_eq!(fold(7, 10), 7);
    }
}
