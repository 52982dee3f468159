//! Synthesising new flames from a trained model, with user controls.
//!
//! Source: stich-magnor-learning-flames.txt §4.3 (sampling the ARP, eq. 2, step by step)
//! and §5.1 (controls: a path offset for wind, height, width and scale; an
//! intensity-to-colour transfer function — the palettes of `ignis-core`).
//!
//! Controls act on the sampled state before rendering, never on the process itself, so
//! the dynamics stay those learned:
//! - `wind`: the path of slice `i` is offset by `wind · tᵢ²`, `tᵢ ∈ (0, 1)` its height
//!   from the bottom of the canonical range: the base stays, the tip bends. Units of
//!   `σ_v` (the flame's main-axis deviation, roughly a fifth of its visible height);
//!   positive bends to the right.
//! - `height`: multiplies the length of the flame while keeping its width in pixels.
//! - `width`: multiplies every slice width.
//! - `scale`: multiplies the whole flame.

use crate::error::{LearnedError, Result};
use crate::model::FlameModel;
use crate::shape::{canonical_box_of, pixel_box, render_scaled_into, Placement, RenderScratch};
use ignis_core::{GrayFrame, Rng, Size};
use serde::{Deserialize, Serialize};

/// Largest wind offset (flame heights): beyond it the flame leaves any frame.
pub const MAX_WIND: f64 = 10.0;

/// Wind (path offset) over time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Wind {
    /// The same offset on every frame.
    Constant(f64),
    /// `(frame, offset)` keys, frames increasing; linear in between, held outside.
    Keys(Vec<(f64, f64)>),
}

impl Default for Wind {
    fn default() -> Self {
        Wind::Constant(0.0)
    }
}

impl Wind {
    /// The offset at frame `t`.
    pub fn at(&self, t: f64) -> f64 {
        match self {
            Wind::Constant(w) => *w,
            Wind::Keys(k) if k.is_empty() => 0.0,
            Wind::Keys(k) => {
                if t <= k[0].0 {
                    return k[0].1;
                }
                for w in k.windows(2) {
                    if t <= w[1].0 {
                        let f = (t - w[0].0) / (w[1].0 - w[0].0).max(1e-12);
                        return w[0].1 + f * (w[1].1 - w[0].1);
                    }
                }
                k[k.len() - 1].1
            }
        }
    }

    /// Parses `0.3` (constant) or `0:0,100:0.5,200:-0.2` (frame:offset keys).
    pub fn parse(s: &str) -> Result<Wind> {
        let bad = || {
            LearnedError::bad(
                "wind",
                format!(
                    "`{s}` is not a number or frame:offset keys like 0:0,100:0.5 \
                     (offsets within ±{MAX_WIND}, in flame heights)"
                ),
            )
        };
        if let Ok(v) = s.trim().parse::<f64>() {
            return if v.is_finite() && v.abs() <= MAX_WIND {
                Ok(Wind::Constant(v))
            } else {
                Err(bad())
            };
        }
        let mut keys = Vec::new();
        for part in s.split(',') {
            let (f, v) = part.split_once(':').ok_or_else(bad)?;
            let (f, v): (f64, f64) = (
                f.trim().parse().map_err(|_| bad())?,
                v.trim().parse().map_err(|_| bad())?,
            );
            if !f.is_finite()
                || !v.is_finite()
                || v.abs() > MAX_WIND
                || keys.last().is_some_and(|&(lf, _): &(f64, f64)| f <= lf)
            {
                return Err(bad());
            }
            keys.push((f, v));
        }
        Ok(Wind::Keys(keys))
    }
}

/// User controls of synthesis (§5.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Controls {
    /// Path offset (bend), see the module docs. Default none.
    pub wind: Wind,
    /// Height multiplier, 0.1..=10. Default 1.
    pub height: f64,
    /// Width multiplier, 0.1..=10. Default 1.
    pub width: f64,
    /// Scale multiplier (whole flame), 0.1..=10. Default 1.
    pub scale: f64,
}

impl Default for Controls {
    fn default() -> Self {
        Controls {
            wind: Wind::default(),
            height: 1.0,
            width: 1.0,
            scale: 1.0,
        }
    }
}

impl Controls {
    pub fn validate(&self) -> Result<()> {
        let winds: Vec<f64> = match &self.wind {
            Wind::Constant(w) => vec![*w],
            Wind::Keys(k) => k.iter().flat_map(|&(f, v)| [f, v]).collect(),
        };
        let ok = match &self.wind {
            Wind::Constant(w) => w.is_finite() && w.abs() <= MAX_WIND,
            Wind::Keys(k) => k
                .iter()
                .all(|&(f, v)| f.is_finite() && v.is_finite() && v.abs() <= MAX_WIND),
        };
        if !ok {
            return Err(LearnedError::bad(
                "wind",
                format!("{winds:?}: offsets must be finite and within ±{MAX_WIND} flame heights"),
            ));
        }
        for (name, v) in [
            ("height", self.height),
            ("width", self.width),
            ("scale", self.scale),
        ] {
            if !(0.1..=10.0).contains(&v) || v.is_nan() {
                return Err(LearnedError::bad(name, format!("{v} is outside 0.1..=10")));
            }
        }
        Ok(())
    }
}

/// An endless, seeded stream of new flames from a model (§4.3).
pub struct Synthesiser<'m> {
    model: &'m FlameModel,
    controls: Controls,
    rng: Rng,
    /// The last `K` states, newest first.
    hist: Vec<Vec<f64>>,
    /// The state before `hist[0]` (kept for interpolation when `K` is 1).
    prev: Vec<f64>,
    /// The current output frame's state, before controls (interpolated in time).
    raw: Vec<f64>,
    /// Process steps per output frame: the model's frame rate over the output's.
    rate: f64,
    /// Output frames rendered or skipped so far.
    frame: u64,
    next: Vec<f64>,
    noise: Vec<f64>,
    shown: Vec<f64>,
    normalised: Vec<f32>,
    scratch: RenderScratch,
    t: u64,
    /// Intensity scale of every rendered frame ([`exposure`]).
    exposure: f32,
    /// A looping synthesiser's states, played in order and over again
    /// ([`Synthesiser::looping`]).
    looped: Option<Vec<Vec<f64>>>,
    /// A loop's period in output frames.
    loop_frames: u32,
    /// The mean flame's extent below and above its centroid, in `σ_v`
    /// ([`FlameModel::mean_extent`], [`Synthesiser::place`]).
    extent: (f64, f64),
    /// The process time (in steps, `0..states`) of each of a loop's frames, re-timed to
    /// constant speed for one output size ([`looptime`]).
    loop_times: Option<(Size, Vec<f64>)>,
    /// How the loop's timing sees an intensity ([`Synthesiser::measure_loop_through`]);
    /// `None`: as a grey writer shows it.
    loop_measure: Option<Vec<f32>>,
}

mod looptime;
mod motion;
pub use motion::{model_motion, Warp};

/// The most state values a loop may hold (frames × state dimension): 64 M (512 MB).
const MAX_LOOP_VALUES: usize = 64 << 20;

impl<'m> Synthesiser<'m> {
    /// Starts from the model's last training states, one process step per output frame;
    /// the same model, controls and seed give the same frames.
    pub fn new(model: &'m FlameModel, controls: Controls, seed: u64) -> Result<Synthesiser<'m>> {
        Synthesiser::new_at(model, controls, seed, None)
    }

    /// As [`Synthesiser::new`], for output at `output_fps` frames per second: the process
    /// runs at the footage's rate (one step per training frame, [`steps_per_frame`]) and
    /// every output frame shows the state at its own time, interpolated linearly between
    /// the two process steps around it, so a 60 fps render of a 30 fps model flickers at
    /// the footage's frequencies, not twice them. `None`, or a model that does not know
    /// its footage's rate, gives one step per frame.
    pub fn new_at(
        model: &'m FlameModel,
        controls: Controls,
        seed: u64,
        output_fps: Option<f64>,
    ) -> Result<Synthesiser<'m>> {
        controls.validate()?;
        let rate = steps_per_frame(model, output_fps)?;
        let n = model.n_state();
        Ok(Synthesiser {
            model,
            controls,
            rng: Rng::new(seed),
            hist: model.init.iter().rev().cloned().collect(),
            prev: vec![0.0; n],
            raw: vec![0.0; n],
            frame: 0,
            next: vec![0.0; n],
            noise: vec![0.0; n],
            shown: vec![0.0; n],
            normalised: Vec::new(),
            scratch: RenderScratch::default(),
            t: 0,
            exposure: exposure(model),
            looped: None,
            loop_frames: 0,
            loop_times: None,
            loop_measure: None,
            extent: model.mean_extent(),
            rate,
        })
    }

    /// A synthesiser whose frames form a seamless loop of `frames` frames: the states are
    /// a sample of the ARP conditioned on returning to its start state
    /// ([`crate::Arp::simulate_loop`]), so frame `frames` would be frame 0 and the step
    /// across the seam is one of the process's own. Not a crossfade: every frame is a
    /// state of the learned process. Frames after the last repeat the loop.
    pub fn looping(
        model: &'m FlameModel,
        controls: Controls,
        seed: u64,
        frames: u32,
    ) -> Result<Synthesiser<'m>> {
        Synthesiser::looping_at(model, controls, seed, frames, None)
    }

    /// As [`Synthesiser::looping`], for output at `output_fps` (see
    /// [`Synthesiser::new_at`]): the loop holds the whole number of process steps nearest
    /// to `frames` output frames' time, and output frame `t` shows the loop's state at a
    /// time re-timed to constant measured speed for the output size (`synth/looptime.rs`:
    /// every step, the wrap included, about as long as the others), interpolated
    /// cyclically, so the period is exactly `frames`.
    pub fn looping_at(
        model: &'m FlameModel,
        controls: Controls,
        seed: u64,
        frames: u32,
        output_fps: Option<f64>,
    ) -> Result<Synthesiser<'m>> {
        let mut s = Synthesiser::new_at(model, controls, seed, output_fps)?;
        if frames < 2 {
            return Err(LearnedError::bad(
                "frames",
                format!("a loop needs at least 2 frames, not {frames}"),
            ));
        }
        let steps = ((frames as f64 * s.rate).round() as usize).max(2);
        if steps.saturating_mul(model.n_state()) > MAX_LOOP_VALUES {
            return Err(LearnedError::bad(
                "frames",
                format!(
                    "a loop of {frames} frames holds {} state values, over the limit of {MAX_LOOP_VALUES}; loop fewer frames",
                    steps * model.n_state()
                ),
            ));
        }
        let start = loop_start(model, seed)?;
        let states = model.arp.simulate_loop(&start, steps, seed)?;
        s.rate = steps as f64 / frames as f64;
        s.looped = Some(states);
        s.loop_frames = frames;
        Ok(s)
    }

    /// Times a loop's frames for the loop measure ([`ignis_core::loopq`]) of frames shown
    /// through `table` rather than written grey: `table[i]` is the measure's value (the
    /// writer's sRGB luma) of a pixel of intensity `i / (table.len() − 1)` as rendered,
    /// `0..=1` (above 1 as at 1), for example after a palette and a gain. Steps are
    /// differences of these values, so only their changes matter. Call before the first
    /// frame; every chunk of a loop must be given the same table.
    ///
    /// Errors when the table has fewer than 2 entries or one that is not finite.
    pub fn measure_loop_through(&mut self, table: Vec<f32>) -> Result<()> {
        if table.len() < 2 || !table.iter().all(|v| v.is_finite()) {
            return Err(LearnedError::bad(
                "loop measure",
                format!(
                    "needs at least 2 finite values, got {} (of which {} finite)",
                    table.len(),
                    table.iter().filter(|v| v.is_finite()).count()
                ),
            ));
        }
        // dark pixels (outside a render's window) must measure 0
        let zero = table[0];
        self.loop_measure = Some(table.into_iter().map(|v| v - zero).collect());
        self.loop_times = None;
        Ok(())
    }

    /// A looping synthesiser's frame times (the process time of each of the loop's frames)
    /// and the frame size they were timed for, once its first frame of that size has timed
    /// them; to give [`Synthesiser::set_loop_times`] later. `None` before, or when not
    /// looping.
    pub fn loop_times(&self) -> Option<(Size, &[f64])> {
        self.loop_times.as_ref().map(|(s, t)| (*s, &t[..]))
    }

    /// Gives a looping synthesiser the frame times an earlier one of the same model,
    /// controls, seed, loop length, rate and loop measure timed for frames of `size`
    /// ([`Synthesiser::loop_times`]), so its frames of that size are that one's, bit for
    /// bit, without timing them again (a render farm's later chunks). Call after
    /// [`Synthesiser::measure_loop_through`], which clears them. Times of another loop
    /// still make a seamless loop, only with less even steps. Errors when not looping, or
    /// on times no loop of this length has (not one per frame, negative or not finite).
    pub fn set_loop_times(&mut self, size: Size, times: Vec<f64>) -> Result<()> {
        if self.looped.is_none() {
            return Err(LearnedError::bad(
                "loop times",
                "given to a synthesiser that does not loop".to_string(),
            ));
        }
        if times.len() != self.loop_frames as usize {
            return Err(LearnedError::bad(
                "loop times",
                format!(
                    "{} times for a loop of {} frames",
                    times.len(),
                    self.loop_frames
                ),
            ));
        }
        if let Some(t) = times.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
            return Err(LearnedError::bad(
                "loop times",
                format!("{t} is not a time in the loop"),
            ));
        }
        self.loop_times = Some((size, times));
        Ok(())
    }

    /// Skips `n` output frames without rendering them (only the cheap process steps run,
    /// when the next frame needs them), so the next frame is exactly the one a full run
    /// would render there: a render-farm chunk.
    pub fn skip(&mut self, n: u64) {
        self.frame += n;
    }

    /// Changes the controls from the next frame on (for interactive steering).
    pub fn set_controls(&mut self, controls: Controls) -> Result<()> {
        controls.validate()?;
        self.controls = controls;
        Ok(())
    }

    /// Samples the next state of the process from the ARP (eq. 2), before controls: one
    /// process step (see [`Synthesiser::new_at`] for output frames at another rate).
    pub fn step(&mut self) -> &[f64] {
        self.prev.copy_from_slice(&self.hist[0]);
        if let Some(states) = &self.looped {
            let x = &states[(self.t % states.len() as u64) as usize];
            let mut last = self.hist.pop().expect("order ≥ 1");
            last.copy_from_slice(x);
            self.hist.insert(0, last);
            self.t += 1;
            return &self.hist[0];
        }
        let hist: Vec<&[f64]> = self.hist.iter().map(|h| h.as_slice()).collect();
        self.model
            .arp
            .step(&hist, &mut self.rng, &mut self.noise, &mut self.next);
        drop(hist);
        let mut last = self.hist.pop().expect("order ≥ 1");
        last.copy_from_slice(&self.next);
        self.hist.insert(0, last);
        self.t += 1;
        &self.hist[0]
    }

    /// Sets `raw` to the state at the next output frame's time: process step
    /// `i = ⌊frame · rate⌋` and, between steps, the linear blend towards step `i + 1`.
    /// A loop's frames are instead at their re-timed times ([`looptime`]) for `size`.
    fn frame_state(&mut self, size: Size) {
        if self.looped.is_some() {
            self.loop_frame_state(size);
            return;
        }
        self.process_state_at(self.frame as f64 * self.rate);
    }

    /// Sets `raw` to the free-running process's state at process time `tau` (steps): step
    /// `i = ⌊tau⌋` and, between steps, the linear blend towards step `i + 1`. Runs the
    /// process on as far as `tau` needs; `tau` must not go back past the last step taken.
    fn process_state_at(&mut self, tau: f64) {
        let i = tau.floor() as u64;
        let frac = tau - i as f64;
        let need = if frac > 1e-9 { i + 2 } else { i + 1 };
        while self.t < need {
            self.step();
        }
        if frac > 1e-9 {
            let (a, b) = (&self.prev, &self.hist[0]);
            for ((r, &a), &b) in self.raw.iter_mut().zip(a).zip(b) {
                *r = a + frac * (b - a);
            }
        } else {
            self.raw.copy_from_slice(&self.hist[0]);
        }
    }

    /// The current output frame's state with the controls applied (what is rendered).
    pub fn controlled_state(&mut self) -> &[f64] {
        self.apply_controls(self.frame as f64);
        &self.shown
    }

    /// Sets `shown` to `raw` with the controls applied, the wind taken at output frame `at`.
    fn apply_controls(&mut self, at: f64) {
        let s = &self.model.shape;
        let (np, nw) = (s.n_path, s.n_width);
        self.shown.copy_from_slice(&self.raw);
        let wind = self.controls.wind.at(at);
        for i in 0..np {
            let t = (i as f64 + 0.5) / np as f64;
            self.shown[i] += wind * t * t / self.controls.height;
        }
        let wmul = self.controls.width / self.controls.height;
        for w in &mut self.shown[np..np + nw] {
            *w = (*w * wmul).max(0.02);
        }
        let h = &mut self.shown[np + nw];
        *h = (*h * self.controls.height * self.controls.scale).max(1e-4);
    }

    /// Samples the next state and renders it into `out` at the model's mean placement.
    pub fn next_frame_into(&mut self, out: &mut GrayFrame) {
        self.frame_state(out.size());
        self.render_raw(self.frame as f64, out);
        self.frame += 1;
    }

    /// Renders `raw` with the controls (wind at output frame `at`) into `out`.
    fn render_raw(&mut self, at: f64, out: &mut GrayFrame) {
        self.render_window(at, out.size(), (0, 0), out);
    }

    /// Renders `raw` as [`Self::render_raw`] into a frame of `size`, of which `out` holds
    /// the window whose top-left pixel is `origin` (pixels outside it are not drawn).
    fn render_window(&mut self, at: f64, size: Size, origin: (u32, u32), out: &mut GrayFrame) {
        self.apply_controls(at);
        let mut place = self.place(size);
        place.cx -= f64::from(origin.0);
        place.cy -= f64::from(origin.1);
        let (shape, w) = self.model.split(&self.shown);
        self.normalised.resize(self.model.pca.n_pixels(), 0.0);
        self.model
            .pca
            .reconstruct_into(&w, w.len(), &mut self.normalised);
        render_scaled_into(
            &self.normalised,
            &shape,
            &place,
            &self.model.shape,
            &mut self.scratch,
            f64::from(size.height),
            out,
        );
        self.expose(out);
    }

    /// The pixel box (`[x_lo, x_hi, y_lo, y_hi]`, see [`pixel_box`]) outside which the
    /// flame of `raw`, with the controls at output frame `at`, lights no pixel of a frame of
    /// each of `sizes`, when only the normalised image's rows and columns `lit` hold light
    /// (see [`canonical_box`]).
    fn raw_boxes<const N: usize>(
        &mut self,
        at: f64,
        lit: [usize; 4],
        sizes: [Size; N],
    ) -> [[f64; 4]; N] {
        self.apply_controls(at);
        let (shape, _) = self.model.split(&self.shown);
        let (path, width) = self.scratch.row_profiles(&shape, &self.model.shape);
        let b = canonical_box_of(path, width, &self.model.shape, lit);
        sizes.map(|size| {
            let sv = (shape.height * f64::from(size.height)).max(1e-3);
            pixel_box(b, &self.place(size), sv)
        })
    }

    /// Where the current flame (`shown`) is drawn in a frame of `size`: with its base
    /// where the model's mean flame has its base ([`FlameModel::placement_for`]), so a
    /// taller state, or a lengthened or scaled one, grows up from the fuel rather than
    /// about its centroid. The state holds no position, only the height `σ_v` about the
    /// centroid; a real flame's base stays on its wick or log while the tip moves, so
    /// anchoring the centroid instead would bob the whole flame up and down (its base off
    /// the fuel, or through the frame's bottom edge) as `σ_v` varies. The base lies
    /// `below` `σ_v` under the centroid along the flame's axis (the mean flame's extent,
    /// [`FlameModel::mean_extent`]).
    fn place(&self, size: Size) -> Placement {
        let mut place = self.model.placement_within(size, self.extent);
        let i = self.model.shape.n_path + self.model.shape.n_width;
        let h = size.height as f64;
        let d = self.extent.0 * (self.shown[i] - self.model.state_mean[i]) * h;
        place.cx += d * place.tilt.sin();
        place.cy -= d * place.tilt.cos();
        place
    }

    /// Applies the model's [`exposure`] to a rendered frame.
    fn expose(&self, out: &mut GrayFrame) {
        if self.exposure != 1.0 {
            let e = self.exposure;
            out.data_mut().iter_mut().for_each(|v| *v *= e);
        }
    }

    /// Renders `frames` frames of `size` (a convenience over [`Self::next_frame_into`]).
    pub fn frames(&mut self, size: Size, frames: usize) -> Result<Vec<GrayFrame>> {
        crate::shape::check_size(size)?;
        Ok((0..frames)
            .map(|_| {
                let mut f = GrayFrame::new(size);
                self.next_frame_into(&mut f);
                f
            })
            .collect())
    }
}

/// The state a loop starts from and returns to: the process run on from the model's last
/// training states until their influence has decayed to 0.1% (`ρⁿ ≤ 10⁻³` for spectral
/// radius `ρ`, 2K..=2000 steps). The last training state can be far from typical — a run
/// of usable frames often ends where the flame dips or leaves the crop — and a loop
/// conditioned on an atypical state passes through it every cycle with large steps around
/// it (measured on `candle.mp4`: wrap 1.8–3.2× the median step). A state of the running
/// process is as ordinary as any other.
fn loop_start(model: &FlameModel, seed: u64) -> Result<Vec<Vec<f64>>> {
    let k = model.arp.order();
    let rho = model.report.spectral_radius;
    let burn = if rho > 0.0 && rho < 1.0 {
        (3.0 * std::f64::consts::LN_10 / -rho.ln()).ceil() as usize
    } else {
        2000
    };
    let burn = burn.clamp(2 * k, 2000);
    let run = model
        .arp
        .simulate(&model.init, burn, seed ^ 0x6c6f_6f70_5f73_7461)?;
    Ok(run[burn - k..].to_vec())
}

/// Process steps per output frame at `output_fps`: the footage's frame rate the model
/// was trained at over `output_fps`; 1 when either is unknown. `output_fps` must be in
/// `1..=1000`.
pub fn steps_per_frame(model: &FlameModel, output_fps: Option<f64>) -> Result<f64> {
    let Some(out) = output_fps else {
        return Ok(1.0);
    };
    if !(1.0..=1000.0).contains(&out) {
        return Err(LearnedError::bad(
            "fps",
            format!("{out} frames per second is outside 1..=1000"),
        ));
    }
    Ok(model.summary.fps.map_or(1.0, |m| m / out))
}

/// The intensity scale of synthesised frames: footage is exposed so a flame's core is at
/// full brightness, but training levels it (a black level drops a lit background, the
/// normalised images are averages), so a model's mean flame may peak far below 1 and
/// render as a dim blob through any palette. Synthesis restores the footage's exposure:
/// the mean flame's brightest 2 % of pixels map to 1 (the palette's hottest colour), as the
/// core of a flame in the footage does. 1 for a model whose mean is dark.
pub fn exposure(model: &FlameModel) -> f32 {
    let mut m: Vec<f32> = model.pca.mean.clone();
    if m.is_empty() {
        return 1.0;
    }
    let k = ((m.len() as f64 * 0.98) as usize).min(m.len() - 1);
    m.select_nth_unstable_by(k, f32::total_cmp);
    let level = m[k];
    if level > 1e-4 {
        1.0 / level
    } else {
        1.0
    }
}

/// Frames of the model's own process [`fit_scale`] renders (after [`FIT_WARM_UP`]), and
/// the seed it draws them with (fixed: the fit depends on the model, the controls and the
/// frame's shape, not on a render's seed or length, so every chunk of a render and every
/// seed of a wedge gets the same framing).
pub const FIT_FRAMES: usize = 400;
/// Process steps [`fit_scale`] runs before it looks (the process forgets its start).
pub const FIT_WARM_UP: usize = 100;
const FIT_SEED: u64 = 0x6669_745f_7363_616c;
/// Brightness (of the exposed grey frame, whose core is 1) above which [`fit_scale`]
/// counts a pixel as flame: faint enough that what it leaves outside does not show as an
/// edge.
pub const FIT_LEVEL: f32 = 0.05;

/// The smallest `scale` a flame is drawn at (see [`Controls::validate`]) and the smallest
/// [`fit_scale`] returns.
pub const MIN_SCALE: f64 = 0.1;

/// The largest scale (at most 1, at least [`MIN_SCALE`]) at which the flame stays inside
/// a frame of `size` in 99 % of its states: a model trained on footage cropped close to the
/// flame draws its taller states through the frame's top edge at scale 1 (the footage's
/// own framing), a flipbook cell with a flat top, and its wider ones through the sides of a
/// narrow frame (a tall torch cell), a cell with a straight edge. A flame is drawn with
/// its base where the mean flame has it ([`FlameModel::placement_for`], centred across the
/// frame) and grows from there, so its reach above the base and to either side of it
/// scales with the scale. [`FIT_FRAMES`] frames of the model's process (seed fixed, one
/// step a frame) are rendered with `controls` at scale 1/3, 192 pixels tall and at least
/// twice as wide (so that no state leaves it, whatever the frame's shape); each one's
/// reach at scale 1 above, left and right of the base is three times the distance from
/// the base to its outermost pixel that way brighter than [`FIT_LEVEL`]. A state is inside
/// at every scale up to the one that puts one of its reaches at a margin of `size`'s frame
/// (4 % of its height below the top, 4 % of its shorter side inside each side), and the
/// scale returned keeps all but 1 % of the states inside. 1 when the flame fits as it is
/// (or shows nothing).
pub fn fit_scale(model: &FlameModel, controls: &Controls, size: Size) -> Result<f64> {
    const SHRINK: f64 = 1.0 / 3.0;
    let h = 192u32;
    let hf = f64::from(h);
    // the frame's width at 192 px tall (its shape), and the wider frame rendered: widened
    // by an even number of pixels, so the flame's pixels sample the same places as in a
    // frame of the shape itself (its centre moves by whole pixels)
    let w = ((u64::from(size.width) * u64::from(h) + u64::from(size.height) / 2)
        / u64::from(size.height).max(1))
    .clamp(1, 8 * u64::from(h)) as u32;
    let wide = w + 2 * (2 * h).saturating_sub(w).div_ceil(2);
    let w = f64::from(w);
    let small = Size::new(wide, h).map_err(|e| LearnedError::bad("size", e.to_string()))?;
    let mut c = controls.clone();
    c.scale = SHRINK;
    let mut synth = Synthesiser::new(model, c, FIT_SEED)?;
    let (below, above) = model.mean_extent();
    let place = model.placement_within(small, (below, above));
    let i = model.shape.n_path + model.shape.n_width;
    // the base, fixed as the flame grows (`Synthesiser::place`), in the rendered frame
    let sv = below * model.state_mean[i] * hf;
    let base_y = place.cy + sv * place.tilt.cos();
    let base_x = place.cx - sv * place.tilt.sin();
    // the room from the base to each margin of `size`'s frame, in frame heights: the
    // vertical placement depends on the height only, and the base lies as far from the
    // frame's centre across in both frames
    let margin_x = 0.04 * w.min(hf) / hf;
    let off_x = (base_x - 0.5 * f64::from(wide)) / hf;
    let room = [
        base_y / hf - 0.04,
        0.5 * w / hf + off_x - margin_x,
        0.5 * w / hf - off_x - margin_x,
    ];
    let mut frame = GrayFrame::new(small);
    let mut fits = Vec::with_capacity(FIT_FRAMES);
    let stride = wide as usize;
    for k in 0..FIT_WARM_UP + FIT_FRAMES {
        synth.next_frame_into(&mut frame);
        if k < FIT_WARM_UP {
            continue;
        }
        let (mut top, mut left, mut right) = (None, usize::MAX, 0usize);
        for (y, row) in frame.data().chunks(stride).enumerate() {
            let Some(l) = row.iter().position(|&v| v > FIT_LEVEL) else {
                continue;
            };
            let r = row.iter().rposition(|&v| v > FIT_LEVEL).unwrap_or(l);
            top.get_or_insert(y);
            left = left.min(l);
            right = right.max(r + 1);
        }
        let Some(top) = top else {
            continue;
        };
        let reach = [
            base_y - top as f64,
            base_x - left as f64,
            right as f64 - base_x,
        ];
        // the largest scale at which this state is inside on every side
        let fit = reach
            .iter()
            .zip(room)
            .filter(|(r, _)| **r > 0.0)
            .map(|(r, room)| room / (r / hf / SHRINK))
            .fold(f64::INFINITY, f64::min);
        fits.push(fit);
    }
    if fits.is_empty() {
        return Ok(1.0);
    }
    fits.sort_by(f64::total_cmp);
    let k = fits.len() - ((fits.len() as f64 * 0.99).ceil() as usize).clamp(1, fits.len());
    let fit = fits[k];
    if fit.is_nan() {
        return Ok(1.0);
    }
    Ok(fit.clamp(MIN_SCALE, 1.0))
}

/// Convenience: the default placement of a model for an output size (re-exported for
/// callers who render states themselves).
pub fn placement(model: &FlameModel, size: Size) -> Placement {
    model.placement_for(size)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wind_parses_and_interpolates() {
        assert_eq!(Wind::parse("0.3").unwrap(), Wind::Constant(0.3));
        let w = Wind::parse("0:0,100:1").unwrap();
        assert!((w.at(50.0) - 0.5).abs() < 1e-12);
        assert_eq!(w.at(500.0), 1.0);
        assert!(Wind::parse("10:0,5:1").is_err());
        assert!(Wind::parse("abc").is_err());
        // Issue 18 defect 10: offsets past ±MAX_WIND are refused.
        for w in ["1e30", "-11", "0:0,10:1e30", "inf"] {
            assert!(Wind::parse(w).is_err(), "{w}");
        }
        let c = Controls {
            wind: Wind::Constant(1e30),
            ..Default::default()
        };
        assert!(c.validate().is_err());
    }
}
