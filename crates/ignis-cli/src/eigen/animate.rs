//! `ignis eigen animate` and `ignis eigen scenario`: an artist's motion list (a TOML
//! scenario, eigenfires thesis §5.1) joined by transitions, coloured (chapter 6) and
//! written by any `ignis-media` writer. The algorithms live in `ignis_eigen::scenario`
//! (parsing, joins) and `ignis_eigen::animate` (rendering); this file reads footage for
//! original colouring and prints the report.

use crate::global::Global;
use anyhow::{Context, Result};
use ignis_core::{RgbaFrame, Size};
use ignis_eigen::render;
use ignis_eigen::scenario::{Plan, Scenario};
use ignis_eigen::{ClipEntry, EigenError, EigenfireDb};
use ignis_eigen::{Footage, FootageOpener, MediaFootage, SyntheticFootage};
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct AnimateArgs {
    /// Scenario file (TOML); `ignis eigen scenario fire.db` prints a commented one.
    pub scenario: PathBuf,
    /// Only find the transitions (auto and morph joins decided as for the render) and print
    /// the table with the frame count the render writes; write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Write only frames A..B (A included, B excluded) of the scenario's N-frame render,
    /// byte for byte as the full render writes them (sequence files keep their frame
    /// numbers), for splitting a render across machines. Only the frames of the chunk (and
    /// the two ends of a morph it cuts into) are rendered.
    #[arg(long, value_name = "A..B")]
    pub chunk: Option<crate::frames::Chunk>,
    #[command(flatten)]
    pub footage: FootageArgs,
    #[command(flatten)]
    pub out: crate::output::OutputArgs,
}

/// Renders `plan` with `look` (footage options and sources from `footage`) into the output
/// `out`, with a progress bar; returns the frame size written.
pub fn write_plan(
    db: &EigenfireDb,
    plan: &Plan,
    look: &ignis_eigen::scenario::Look,
    footage: &FootageArgs,
    out: &crate::output::OutputArgs,
    g: &Global,
) -> Result<Size> {
    write_plan_chunk(db, plan, None, look, footage, out, g)
}

/// [`write_plan`] of only the frames `chunk` of the plan (all of them for `None`), as the
/// full render writes them: sequence files keep their frame numbers and a chunk is not
/// marked as a loop. `chunk` must lie inside the plan (see [`check_chunk`]).
pub fn write_plan_chunk(
    db: &EigenfireDb,
    plan: &Plan,
    chunk: Option<std::ops::Range<usize>>,
    look: &ignis_eigen::scenario::Look,
    footage: &FootageArgs,
    out: &crate::output::OutputArgs,
    g: &Global,
) -> Result<Size> {
    let mut opts = footage.options()?;
    let mut sources = footage.sources(db)?;
    let n = plan.frames.len();
    let (sub, emit) = match &chunk {
        Some(r) if *r != (0..n) => {
            let (sub, emit) = chunk_plan(db, plan, r.clone());
            (Some(sub), emit)
        }
        _ => (None, vec![true; n]),
    };
    let mut wopts = out.write_options();
    if out.fps.is_none() {
        let (fps, note) = plan_rate(db, plan);
        wopts.fps = fps;
        if let Some(note) = note {
            g.say(note);
        }
    }
    if let Some(r) = chunk.as_ref().filter(|r| **r != (0..n)) {
        wopts.loop_ = false;
        wopts.first_frame = r.start as u64;
    }
    let size = fit_plan_size(db, plan, &emit, &mut opts, &mut wopts, out, g)?;
    let mut w = out.create_with(size, &wopts)?;
    let bar = g.progress(emit.iter().filter(|&&e| e).count() as u64, "rendering");
    let mut at = 0usize;
    let mut sink = |f: RgbaFrame| -> ignis_eigen::Result<()> {
        let keep = emit.get(at).copied().unwrap_or(false);
        at += 1;
        if !keep {
            return Ok(());
        }
        bar.inc(1);
        let f = if f.size() == size {
            f
        } else {
            f.centred_in(size)
        };
        w.push(&f).map_err(|e| EigenError::BadParameter {
            name: "output".into(),
            reason: format!("{}: {e}", out.output.display()),
        })
    };
    let plan = sub.as_ref().unwrap_or(plan);
    render::render_plan_with(db, plan, look, &opts, &mut sources, &mut sink, &mut |_| {})?;
    bar.finish_and_clear();
    out.finish(w, g)?;
    Ok(size)
}

/// The rate `plan` plays at when `--fps` is not given: its footage frames' own (a clip's
/// rate over its training stride), so a 24-fps clip is not written at 30 fps and played
/// 25 % fast. A plan that mixes clips of different rates plays at the rate of most of its
/// footage frames, with a note naming the rates and `--fps`; one with no footage frame at
/// the default rate.
pub fn plan_rate(db: &EigenfireDb, plan: &Plan) -> (f64, Option<String>) {
    use ignis_eigen::transition::FrameRef;
    // (rate, frames at it), in order of first use
    let mut rates: Vec<(f64, usize)> = Vec::new();
    for f in &plan.frames {
        let FrameRef::Db(row) = f.source else {
            continue;
        };
        let Some((clip, _)) = db.row_origin(row) else {
            continue;
        };
        let rate = clip.fps / clip.stride.max(1) as f64;
        match rates.iter_mut().find(|(r, _)| *r == rate) {
            Some((_, n)) => *n += 1,
            None => rates.push((rate, 1)),
        }
    }
    let Some(&(fps, _)) = rates.iter().rev().max_by_key(|(_, n)| *n) else {
        return (crate::output::DEFAULT_FPS, None);
    };
    let note = (rates.len() > 1).then(|| {
        let shown = |r: f64| (r * 1000.0).round() / 1000.0;
        let all: Vec<String> = rates.iter().map(|&(r, _)| shown(r).to_string()).collect();
        format!(
            "the frames come from clips at {} fps: writing at {} fps, the rate of most of \
             them (give --fps to choose another)",
            all.join(", "),
            shown(fps)
        )
    });
    (fps, note)
}

/// The frame size to render `plan` at, settled before anything is rendered: the user's
/// `--size` (a flipbook it does not fit is refused here, with the fix), else the source
/// clip's own size — for a flipbook whose full-size cells do not fit the sheet limit,
/// scaled down as `ignis loop` scales ([`crate::output::OutputArgs::fit_flipbook`]: the
/// note printed, `scaled_from` in the JSON, `opts.size` set to the cells). A chunk's frames
/// are sized for the whole plan, so they are the full render's frames; an explicit size
/// is checked against the frames the writer gets (`emit`).
fn fit_plan_size(
    db: &EigenfireDb,
    plan: &Plan,
    emit: &[bool],
    opts: &mut render::RenderOptions,
    wopts: &mut ignis_media::WriteOptions,
    out: &crate::output::OutputArgs,
    g: &Global,
) -> Result<Size> {
    let natural = render::output_size(db, plan);
    let (size, explicit) = match opts.size {
        Some(s) => (s, true),
        None => (natural, false),
    };
    let n = if explicit {
        emit.iter().filter(|&&e| e).count()
    } else {
        plan.frames.len()
    };
    let fitted = out.fit_flipbook(n, size, explicit, wopts)?;
    if let Some(note) = fitted.note() {
        g.say(note);
        opts.size = Some(fitted.size);
    }
    // A --size of another aspect than the footage's view: rendered to fit inside it and
    // centred with transparent borders (write_plan_chunk's sink), never stretched.
    let inside = natural.fitted_inside(fitted.size);
    if explicit && inside != fitted.size {
        g.say(format!(
            "size: the {natural} view fitted inside {} at {inside}, centred, with transparent \
             borders (never stretched)",
            fitted.size
        ));
        opts.size = Some(inside);
    }
    Ok(fitted.size)
}

/// `--chunk A..B` checked against a plan of `n` frames.
pub fn check_chunk(chunk: crate::frames::Chunk, n: usize) -> Result<std::ops::Range<usize>> {
    let (a, b) = (chunk.start as usize, chunk.end as usize);
    anyhow::ensure!(
        a < b && b <= n,
        "--chunk {a}..{b} is not a range of frames inside 0..{n} (the scenario renders {n} frames); give A..B with A < B ≤ {n}"
    );
    Ok(a..b)
}

/// The plan that renders frames `range` of `plan` and as little else as gives the same
/// bytes, and which of its frames (in render order) are the chunk's. Every frame of a plan
/// renders on its own except a morph, made from the two frames around its run: a run the
/// chunk cuts into is kept whole, between copies of its two end frames. The output view
/// depends on which clips the plan shows, so one frame of each clip the chunk lacks is put
/// first (rendered, not written). Automatic morph runs must be resolved
/// ([`ignis_eigen::animate::morph::resolve`]): their in-betweens would otherwise be chosen from
/// the chunk's neighbours, not the full render's.
fn chunk_plan(db: &EigenfireDb, plan: &Plan, range: std::ops::Range<usize>) -> (Plan, Vec<bool>) {
    use ignis_eigen::scenario::MorphRun;
    use ignis_eigen::transition::FrameRef;
    let n = plan.frames.len();
    let clip_of = |i: usize| match plan.frames[i].source {
        FrameRef::Db(r) => db.row_origin(r).map(|(c, _)| c.name.clone()),
        FrameRef::Weights(_) => None,
    };
    // (index in the plan, written)
    let mut picks: Vec<(usize, bool)> = Vec::new();
    let mut morphs = Vec::new();
    let mut i = range.start;
    while i < range.end {
        if let Some(r) = plan
            .morphs
            .iter()
            .find(|r| r.start <= i && i < r.start + r.len)
        {
            let (a, b) = r.endpoints(n);
            if picks.last().map(|p| p.0) != Some(a) {
                picks.push((a, false));
            }
            morphs.push((picks.len()..picks.len() + r.len, r));
            picks.extend((r.start..r.start + r.len).map(|j| (j, range.contains(&j))));
            picks.push((b, false));
            i = r.start + r.len;
        } else {
            match picks.last_mut() {
                // the end frame of the run just kept
                Some((j, w)) if *j == i => *w = true,
                _ => picks.push((i, true)),
            }
            i += 1;
        }
    }
    let mut shown: Vec<Option<String>> = picks.iter().map(|p| clip_of(p.0)).collect();
    let mut extra = Vec::new();
    for j in 0..n {
        if let Some(c) = clip_of(j) {
            if !shown.contains(&Some(c.clone())) {
                shown.push(Some(c));
                extra.push((j, false));
            }
        }
    }
    let lead = extra.len();
    extra.extend(picks);
    let sub = Plan {
        frames: extra.iter().map(|p| plan.frames[p.0].clone()).collect(),
        morphs: morphs
            .into_iter()
            .map(|(m, r)| MorphRun {
                start: m.start + lead,
                len: m.len(),
                fixed: r.fixed,
                times: r.times.clone(),
            })
            .collect(),
        ..plan.clone()
    };
    (sub, extra.iter().map(|p| p.1).collect())
}

/// Output size and where the footage comes from (`eigen animate`, `eigen loop`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct FootageArgs {
    /// Output size WIDTHxHEIGHT (default: the source clip's own size; a database of
    /// clips of different sizes shown together: the common frame). A size of another aspect
    /// gets the view fitted inside it, centred, with transparent borders (never stretched).
    /// Example: --size 1280x720
    #[arg(long, value_parser = parse_size)]
    pub size: Option<Size>,
    /// The source video of CLIP is now at PATH (repeatable): CLIP=PATH. It must have the
    /// frame size and frame count the database was trained on. Example:
    /// --relink candle=/footage/candle.mp4
    #[arg(long, value_parser = parse_relink)]
    pub relink: Vec<(String, PathBuf)>,
    /// Do not read the source videos for the grey frames: database frames are
    /// reconstructed from the Eigenfires (or taken from stored frames). Original colouring
    /// becomes synthetic colouring (it needs the footage).
    #[arg(long)]
    pub from_database: bool,
}

/// `WIDTHxHEIGHT`, any numbers (the size is checked with a clear message later).
pub fn parse_size(s: &str) -> std::result::Result<Size, String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT (e.g. 1280x720)"))?;
    let n = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("`{v}` in `{s}` is not a whole number of pixels"))
    };
    Ok(Size {
        width: n(w)?,
        height: n(h)?,
    })
}

fn parse_relink(s: &str) -> std::result::Result<(String, PathBuf), String> {
    let (c, p) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not CLIP=PATH (e.g. candle=/footage/candle.mp4)"))?;
    if c.is_empty() || p.is_empty() {
        return Err(format!(
            "`{s}` is not CLIP=PATH (e.g. candle=/footage/candle.mp4)"
        ));
    }
    Ok((c.to_string(), PathBuf::from(p)))
}

impl FootageArgs {
    /// The render options, with `--size` checked.
    pub fn options(&self) -> Result<render::RenderOptions> {
        if let Some(s) = self.size {
            render::check_output_size(s).context("--size")?;
        }
        Ok(render::RenderOptions {
            size: self.size,
            from_database: self.from_database,
            batch: None,
        })
    }

    /// The footage reader, with `--relink` checked against the database's clips.
    pub fn sources(&self, db: &EigenfireDb) -> Result<MediaSources> {
        for (c, _) in &self.relink {
            db.clip(c).context("--relink")?;
        }
        Ok(MediaSources {
            relink: self.relink.iter().cloned().collect(),
            ..Default::default()
        })
    }

    /// `look` adjusted for `--from-database`; says what changed.
    pub fn adjust_look(&self, look: &mut ignis_eigen::scenario::Look, g: &Global) {
        if self.from_database && matches!(look.mode, ignis_eigen::scenario::ColourMode::Original) {
            look.mode = ignis_eigen::scenario::ColourMode::Synthetic;
            g.say(
                "--from-database: original colouring needs the footage; using synthetic colouring",
            );
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct ScenarioArgs {
    /// Database directory the scenario is for.
    pub db: PathBuf,
}

/// [`FootageOpener`] over `ignis-media`, falling back to redrawing synthetic clips. A
/// clip's recorded source is checked once against the fingerprint taken at training
/// (size, SHA-256, frame count); `relink` gives a clip's footage a new place (checked
/// for the trained frame size and count).
#[derive(Default)]
pub struct MediaSources {
    pub relink: std::collections::HashMap<String, PathBuf>,
    pub checked: std::collections::HashSet<String>,
    /// Footage opened so far (probed once per file and crop: two clips may be two parts
    /// of one video).
    opened: std::collections::HashMap<(PathBuf, Option<[u32; 4]>), MediaFootage>,
}

impl MediaSources {
    /// The footage of `clip` (its `--relink` place, else the path recorded at training),
    /// checked as a render checks it (missing, or changed since training).
    pub fn checked_path(&mut self, clip: &ClipEntry) -> ignis_eigen::Result<PathBuf> {
        let p = self
            .relink
            .get(&clip.name)
            .cloned()
            .unwrap_or_else(|| PathBuf::from(&clip.source));
        self.check(clip, &p)?;
        Ok(p)
    }

    fn check(&mut self, clip: &ClipEntry, p: &Path) -> ignis_eigen::Result<()> {
        if self.checked.contains(&clip.name) {
            return Ok(());
        }
        let relinked = self.relink.contains_key(&clip.name);
        // A file, or an image sequence with frames (a directory or `frames/%04d.png`).
        let sequence =
            || ignis_media::source_files(p).is_ok_and(|f| f.len() != 1 || f[0].as_path() != p);
        if !p.is_file() && !sequence() {
            return Err(EigenError::clip(
                &clip.name,
                format!(
                    "the source video {} is missing; give its new place with --relink {}=PATH, or render reconstructed frames with --from-database",
                    p.display(),
                    clip.name
                ),
            ));
        }
        let info = ignis_media::probe(p).map_err(|e| EigenError::Decode {
            what: format!("clip `{}` ({})", clip.name, p.display()),
            frame: None,
            source: Box::new(e),
        })?;
        let frames = info.frame_count.map(|n| n as usize);
        // a clip trained on part of the frame is that part of it
        let mut info = info;
        if let Some(c) = clip.crop {
            info.size = crate::args::crop_inside(&crate::eigen::rect(c), info.size, p)
                .map_err(|e| EigenError::clip(&clip.name, e.to_string()))?;
        }
        if relinked {
            let count_ok = match (
                clip.source_check.as_ref().and_then(|c| c.frame_count),
                frames,
            ) {
                (Some(a), Some(b)) => a == b,
                _ => frames.is_none_or(|n| n >= clip.end),
            };
            if info.size != clip.source_size || !count_ok {
                return Err(EigenError::clip(
                    &clip.name,
                    format!(
                        "--relink {}: {} is {}{}, the clip was trained on {}{}; relink the clip's own footage",
                        clip.name,
                        p.display(),
                        info.size,
                        frames.map_or(String::new(), |n| format!(" with {n} frames")),
                        clip.source_size,
                        clip.source_check
                            .as_ref()
                            .and_then(|c| c.frame_count)
                            .map_or(String::new(), |n| format!(" with {n} frames")),
                    ),
                ));
            }
        } else if let Some(c) = &clip.source_check {
            c.verify(&clip.name, p, frames)?;
        } else if info.size != clip.source_size {
            return Err(EigenError::clip(
                &clip.name,
                format!(
                    "the source video {} is {}, the clip was trained on {}; it changed since training: --relink {}=PATH to the original, or --from-database",
                    p.display(),
                    info.size,
                    clip.source_size,
                    clip.name
                ),
            ));
        }
        self.checked.insert(clip.name.clone());
        Ok(())
    }
}

impl FootageOpener for MediaSources {
    fn open(
        &mut self,
        clip: &ClipEntry,
        path: Option<&Path>,
    ) -> ignis_eigen::Result<Box<dyn Footage + '_>> {
        let relinked = self.relink.get(&clip.name).cloned();
        if path.is_none() && relinked.is_none() {
            if let Some(f) = SyntheticFootage::of_clip(clip) {
                return Ok(Box::new(f));
            }
        }
        let p = match (path, &relinked) {
            (Some(p), _) => p.to_path_buf(),
            (None, Some(r)) => r.clone(),
            (None, None) => PathBuf::from(&clip.source),
        };
        if path.is_none() {
            self.check(clip, &p)?;
        }
        let key = (p.clone(), clip.crop);
        if !self.opened.contains_key(&key) {
            let label = format!(
                "clip `{}` ({}{})",
                clip.name,
                p.display(),
                if path.is_none() {
                    ", the path recorded at training; give the footage under [originals] in the scenario"
                } else {
                    ""
                }
            );
            let mut f = MediaFootage::open(&p).map_err(|e| e.in_clip(&clip.name))?;
            if let Some(c) = clip.crop {
                f = f
                    .cropped(crate::eigen::rect(c))
                    .map_err(|e| e.in_clip(&clip.name))?;
            }
            let f = f.labelled(label);
            self.opened.insert(key.clone(), f);
        }
        Ok(Box::new(&self.opened[&key]))
    }
}

fn print_table(g: &Global, plan: &Plan, sc: &Scenario, out_loops: bool) {
    let joins = ignis_eigen::JoinReport::of_plan(plan);
    g.say(ignis_eigen::JoinReport::header());
    for j in &joins {
        g.say(j.row());
    }
    for j in &joins {
        g.say(j.why());
        if let Some(w) = j.warning() {
            g.say(w);
        }
    }
    g.say(format!(
        "{} frames, E = {} for rendering{}, E = {} for detection; largest step {:.2}; wrap (last → first) seam ratio {:.2}{}",
        plan.frames.len(),
        plan.e_render,
        if plan.e_render != plan.e_render_requested {
            format!(" (asked {}, clamped to the usable Eigenfires)", plan.e_render_requested)
        } else {
            String::new()
        },
        plan.e_detect,
        plan.worst_step,
        plan.wrap_seam,
        if plan.loops { " (loop = true)" } else { "" }
    ));
    if out_loops && !sc.is_loop() && plan.wrap_seam > 1.5 {
        g.say(format!(
            "warning: the output loops but the scenario does not (wrap seam ratio {:.2} > 1.5); set `loop = true` in {} or pass --no-loop",
            plan.wrap_seam,
            sc.file().display()
        ));
    }
}

/// Warns when the matte keys out all the fire of some of the frames the render takes
/// from the footage (original colouring with the matte): those frames are written fully
/// transparent. Names them as stretches of output frames. (`eigen loop --range` refuses
/// such a window; a scenario is the user's own sequence, so here it is a warning.)
fn warn_keyed_out(
    db: &EigenfireDb,
    plan: &Plan,
    look: &ignis_eigen::scenario::Look,
    g: &Global,
) -> Result<()> {
    use ignis_eigen::transition::FrameRef;
    if !look.matte || !matches!(look.mode, ignis_eigen::scenario::ColourMode::Original) {
        return Ok(());
    }
    let row = |f: &ignis_eigen::scenario::PlanFrame| match f.source {
        FrameRef::Db(r) => Some(r),
        FrameRef::Weights(_) => None,
    };
    let mut rows: Vec<usize> = plan.frames.iter().filter_map(row).collect();
    rows.sort_unstable();
    rows.dedup();
    let dark: std::collections::HashSet<usize> = ignis_eigen::animate::keyed_out_rows(db, &rows)?
        .into_iter()
        .collect();
    if dark.is_empty() {
        return Ok(());
    }
    let out: Vec<usize> = (0..plan.frames.len())
        .filter(|&i| row(&plan.frames[i]).is_some_and(|r| dark.contains(&r)))
        .collect();
    let mut spans: Vec<(usize, usize)> = Vec::new();
    for &i in &out {
        match spans.last_mut() {
            Some(s) if s.1 == i => s.1 = i + 1,
            _ => spans.push((i, i + 1)),
        }
    }
    let list: Vec<String> = spans
        .iter()
        .take(6)
        .map(|(a, b)| format!("{a}..{b}"))
        .collect();
    let more = if spans.len() > 6 { ", …" } else { "" };
    g.say(format!(
        "warning: the matte keys out all the fire of {} of the {} output frames (output frames {}{more}): \
         they are written fully transparent; choose motion ranges where the fire burns, or set \
         `alpha = \"opaque\"` under [colour]",
        out.len(),
        plan.frames.len(),
        list.join(", ")
    ));
    Ok(())
}

/// `ignis eigen animate`; returns the plan (for the demo's captions).
pub fn animate_cmd(a: &AnimateArgs, g: &Global) -> Result<Plan> {
    let sc = Scenario::from_file(&a.scenario)?;
    let db = EigenfireDb::open(&sc.database).with_context(|| {
        format!(
            "opening the database {} named in {}",
            sc.database.display(),
            a.scenario.display()
        )
    })?;
    let plan = sc.plan(&db, &mut crate::global::StageBars::new(g))?;
    let mut look = sc.look.clone();
    a.footage.adjust_look(&mut look, g);
    // `auto` joins are decided on their rendered frames, and the morph joins' in-between
    // counts too — also for a dry run, so the frame count it prints (what `--chunk` ranges
    // over, the progress bar) is the one written.
    let plan = if plan.joins.iter().all(|j| j.alternatives.is_empty()) {
        plan
    } else {
        let mut sources = a.footage.sources(&db)?;
        sc.measure_joins(&db, plan, &look, &a.footage.options()?, &mut sources)
            .with_context(|| format!("measuring the auto joins of {}", a.scenario.display()))?
    };
    let opts = a.out.write_options();
    let out_loops = opts.loop_
        && matches!(
            a.out.output_format(),
            Some(ignis_media::Format::Gif | ignis_media::Format::Flipbook)
        );
    let plan = if plan.morphs.iter().any(|r| r.times.is_none() && !r.fixed) {
        let mut sources = a.footage.sources(&db)?;
        ignis_eigen::animate::morph::resolve(&db, &plan, &look, &a.footage.options()?, &mut sources)
            .with_context(|| format!("choosing the morph joins of {}", a.scenario.display()))?
    } else {
        plan
    };
    print_table(g, &plan, &sc, out_loops);
    warn_keyed_out(&db, &plan, &look, g)?;
    if a.dry_run {
        a.chunk
            .map(|c| check_chunk(c, plan.frames.len()))
            .transpose()?;
        return Ok(plan);
    }
    let chunk = a
        .chunk
        .map(|c| check_chunk(c, plan.frames.len()))
        .transpose()?;
    let size = write_plan_chunk(&db, &plan, chunk.clone(), &look, &a.footage, &a.out, g)
        .with_context(|| format!("rendering {}", a.scenario.display()))?;
    g.say(format!(
        "{} frames at {size}, colour {}{}{}",
        chunk.map_or(plan.frames.len(), |r| r.len()),
        look.mode.name(),
        if look.bloom.is_some() { " + bloom" } else { "" },
        if look.smoke.is_some() { " + smoke" } else { "" },
    ));
    Ok(plan)
}

/// A commented scenario for `db`: every clip as a motion, joined with each method.
pub fn template(db: &EigenfireDb, db_path: &str) -> String {
    let mut s = String::new();
    s.push_str("# Ignis scenario (eigenfires thesis §5.1): motions joined by transitions.\n");
    s.push_str("# Render: ignis eigen animate scene.toml -o fire.mp4\n");
    s.push_str(&format!("database = {db_path:?}\n"));
    let clips = db.clips();
    let mut names = Vec::new();
    let mut notes = Vec::new();
    for c in clips {
        // The first and last thirds of each clip's fire, so every join has a gap to bridge.
        let (lit, n) = burning(db, c);
        if (lit, n) != (0, c.frames) {
            let frame = |j: usize| c.start + j * c.stride;
            notes.push(format!(
                "# {}: the matte shows fire in frames {}..{} only (the longest such stretch); its motions keep to them\n",
                c.name,
                frame(lit),
                frame(lit + n - 1) + 1
            ));
        }
        let third = (n / 3).max(1);
        let at = |j: usize| c.start + (lit + j) * c.stride;
        names.push((format!("{}-a", c.name), c, at(0), at(third)));
        if n >= 3 {
            let end = if lit + n == c.frames {
                c.end
            } else {
                at(n - 1) + 1
            };
            names.push((format!("{}-b", c.name), c, at(n - third), end));
        }
    }
    s.extend(notes);
    let seq: Vec<String> = names.iter().map(|n| format!("{:?}", n.0)).collect();
    s.push_str(&format!("sequence = [{}]\n", seq.join(", ")));
    s.push_str("loop = true                 # join the last motion back to the first\n");
    s.push_str(&format!(
        "# e_detect = {}              # E for detection (database default)\n# e_render = {}              # E for rendering (database default)\n\n",
        db.manifest().e_detect,
        db.manifest().e_render
    ));
    for (name, c, lo, hi) in &names {
        s.push_str(&format!(
            "[motions.{name}]\nclip = {:?}\nstart = {lo}\nend = {hi}               # excluded; source frame numbers\n# weights = \"1=0.5\"        # §5.2: set Eigenfire weights on every frame\n\n",
            c.name
        ));
    }
    s.push_str("[transition]                # defaults for every join\nmethod = \"auto\"             # auto | end-growing | direct | low-pass | morph\n\n");
    s.push_str("# [[join]]                  # join 1 (positional), overrides [transition]\n# method = \"end-growing\"\n# steps = 40                # N: most frames (end-growing) / frames (direct)\n# theta_min = 2.5           # fixed θ_min (default: adaptive, per clip)\n# kernel = [0.2, 0.2, 0.6]  # low-pass\n# eigenfires = 50           # low-pass: E of the morphs\n\n");
    s.push_str("[colour]\nmode = \"original\"           # original (Algorithm 2) | synthetic | palette | grey\n# tint = [1.0, 0.42, 0.08]  # synthetic colour; in original mode the bloom's tint (default: each clip's own flame colour, measured at training)\n# palette = \"candle\"        # palette mode\nthreshold = 0.013           # original: copy the footage above this grey level (thesis 30/255)\nalpha = \"matte\"             # matte | opaque\nfast_path = true            # §7.1.2: stored pre-processed frames for database frames\n# mask_mode = \"add\"         # add | replace (custom masks, §6.4)\n\n");
    s.push_str("[bloom]\npasses = 3\nradius = 24.0\nstrength = 0.4\n\n");
    s.push_str("# [smoke]                   # §6.3 (original mode)\n# threshold = 0.03\n# blur = 1.0\n# colour = [0.35, 0.35, 0.35]\n\n");
    s.push_str(
        "# [originals]               # colour footage per clip (default: the training source)\n",
    );
    for c in clips {
        s.push_str(&format!("# {} = {:?}\n", c.name, c.source));
    }
    s.push_str("\n# [masks]                   # custom masks per clip, numbered like the clip's frames\n# candle = \"masks/%04d.png\"\n");
    s
}

/// The longest stretch of `c`'s training frames whose matte shows fire, as (first frame,
/// frames) counted in training frames: a motion over frames the matte keys out entirely
/// renders nothing (a fireball's dark start and end). The whole clip when none is keyed
/// out, when none shows fire, or when the database stores no masks.
fn burning(db: &EigenfireDb, c: &ignis_eigen::db::ClipEntry) -> (usize, usize) {
    let rows: Vec<usize> = (c.first_row..c.first_row + c.frames).collect();
    let dark: std::collections::HashSet<usize> =
        match ignis_eigen::animate::keyed_out_rows(db, &rows) {
            Ok(d) => d.into_iter().collect(),
            Err(_) => return (0, c.frames),
        };
    let mut best = (0, 0);
    let mut run_start = 0;
    for j in 0..=c.frames {
        if j == c.frames || dark.contains(&(c.first_row + j)) {
            if j - run_start > best.1 {
                best = (run_start, j - run_start);
            }
            run_start = j + 1;
        }
    }
    if best.1 == 0 {
        (0, c.frames)
    } else {
        best
    }
}

pub fn scenario_cmd(a: &ScenarioArgs) -> Result<()> {
    let db = EigenfireDb::open(&a.db)
        .with_context(|| format!("opening the database {}", a.db.display()))?;
    // The scenario resolves paths against its own directory, which is unknown here (the
    // text goes to stdout): name the database absolutely so it resolves from anywhere.
    let abs = std::path::absolute(&a.db).unwrap_or_else(|_| a.db.clone());
    out!("{}", template(&db, &abs.to_string_lossy()))?;
    Ok(())
}

/// Writes `text` as the scenario `rel` in the demo directory.
/// How a scenario file at `scenario` names the database at `db`: a scenario resolves
/// relative paths against its own directory, so a database beside (or below) it is named
/// relative to it (the demo folder can then be moved), anything else absolutely.
fn relative_to_scenario(db: &Path, scenario: &Path) -> String {
    let dir = scenario.parent().unwrap_or(Path::new(""));
    match db.strip_prefix(dir) {
        Ok(rel) if !dir.as_os_str().is_empty() => rel.to_string_lossy().into_owned(),
        _ => std::path::absolute(db)
            .unwrap_or_else(|_| db.to_path_buf())
            .to_string_lossy()
            .into_owned(),
    }
}

fn write_scenario(ctx: &crate::demo::Demo, rel: &str, text: &str) -> Result<PathBuf> {
    let p = ctx.path(rel)?;
    std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
    Ok(p)
}

/// Renders scenario `rel` to `out_rel` for the demo and adds it to the gallery.
fn demo_render(ctx: &mut crate::demo::Demo, rel: &str, out_rel: &str, what: &str) -> Result<()> {
    let g = Global { quiet: true };
    let sp = ctx.path(rel)?.to_string_lossy().into_owned();
    let op = ctx.path(out_rel)?.to_string_lossy().into_owned();
    let argv = ["animate", sp.as_str(), "-o", op.as_str()];
    let plan = animate_cmd(&crate::parse_sub::<AnimateArgs>(&argv)?, &g)
        .with_context(|| format!("demo scenario {rel}"))?;
    let joins: Vec<String> = plan
        .joins
        .iter()
        .map(|j| {
            format!(
                "{} → {}: {} ({} frames, seam ratio {:.2}, plain cut {:.2})",
                j.from,
                j.to,
                j.join.method,
                j.join.frames.len(),
                j.join.seam_ratio,
                j.plain_cut
            )
        })
        .collect();
    ctx.item(
        out_rel,
        &format!("{what}: {}", joins.join("; ")),
        &format!("ignis eigen animate {rel} -o {out_rel}"),
    );
    Ok(())
}

/// `methods` (one per join of `seq`, looping), with any that finds no path on `db`
/// replaced by `auto` — End Growing can legitimately fail between very different flames
/// (the thesis's case 3), and the demo must not.
fn workable(
    db: &EigenfireDb,
    motions: &[(&str, &str, usize, usize)],
    seq: &[&str],
    methods: &[&str],
) -> Result<Vec<&'static str>> {
    use ignis_eigen::transition::{self, WeightSpace};
    let space = WeightSpace::from_db(db)?;
    let rec = ignis_eigen::animate::recognition_params(db);
    let rows = |name: &str| -> Result<std::ops::Range<usize>> {
        let m = motions
            .iter()
            .find(|m| m.0 == name)
            .expect("motion of the demo");
        Ok(ignis_eigen::animate::clip_rows(db, m.1, m.2..m.3)?)
    };
    let mut out = Vec::new();
    for (i, m) in methods.iter().enumerate() {
        let (a, b) = (rows(seq[i])?, rows(seq[(i + 1) % seq.len()])?);
        let t = ignis_eigen::animate::parse_method(m)?;
        let ok = transition::transition(&space, a, b, &t, &rec).is_ok();
        out.push(match (ok, *m) {
            (true, "end-growing") => "end-growing",
            (true, "direct") => "direct",
            (true, "low-pass") => "low-pass",
            _ => "auto",
        });
    }
    Ok(out)
}

/// The scenario text of the demo: `motions` as (name, clip, start, end), joined in
/// `sequence` order with `methods` (one per join), looping.
fn demo_scenario(
    db: &str,
    motions: &[(&str, &str, usize, usize)],
    sequence: &[&str],
    methods: &[&str],
    colour: &str,
) -> String {
    let mut s = format!("database = {db:?}\nsequence = {sequence:?}\nloop = true\n\n");
    for (name, clip, a, b) in motions {
        s.push_str(&format!(
            "[motions.{name}]\nclip = {clip:?}\nstart = {a}\nend = {b}\n\n"
        ));
    }
    for m in methods {
        s.push_str(&format!("[[join]]\nmethod = {m:?}\n\n"));
    }
    s.push_str(colour);
    s
}

/// The Eigenfires II part of `ignis demo`: a scenario with every transition method and a
/// loop, in original and synthetic colouring, on the synthetic database `dbp`; and, when
/// `../shared/data` is present (full demo only), the same on candle.mp4 + campfire.mp4.
pub fn demo(ctx: &mut crate::demo::Demo, dbp: &Path) -> Result<()> {
    let db = EigenfireDb::open(dbp)?;
    let (c, f) = (db.clip("candle")?, db.clip("campfire")?);
    let half = |e: &ClipEntry| e.start + (e.frames / 2) * e.stride;
    let motions = [
        ("calm", "candle", c.start, half(c)),
        ("tall", "candle", half(c), c.end),
        // Two thirds of the campfire clip: its wide → wide loop then has the last third
        // to bridge through (a join never uses frames of its own two motions).
        (
            "wide",
            "campfire",
            f.start,
            f.start + (2 * f.frames / 3) * f.stride,
        ),
    ];
    // Joins: calm → tall (same clip), tall → wide, wide → wide (a campfire loop inside
    // the sequence), wide → calm (the loop back to the start).
    let seq = ["calm", "tall", "wide", "wide"];
    let methods = workable(
        &db,
        &motions,
        &seq,
        &["end-growing", "auto", "direct", "low-pass"],
    )?;
    for (mode, extra) in [
        (
            "original",
            "[colour]\nmode = \"original\"\n\n[smoke]\nthreshold = 0.02\n",
        ),
        (
            "synthetic",
            "[colour]\nmode = \"synthetic\"\ntint = [1.0, 0.35, 0.05]\n",
        ),
    ] {
        let rel = format!("eigen/scenario-{mode}.toml");
        let dbs = relative_to_scenario(dbp, &ctx.path(&rel)?);
        write_scenario(
            ctx,
            &rel,
            &demo_scenario(&dbs, &motions, &seq, &methods, extra),
        )?;
        demo_render(
            ctx,
            &rel,
            &format!("eigen/scenario-{mode}.gif"),
            &format!("Scenario calm → tall → wide → wide → (loop), {mode} colouring"),
        )?;
    }
    if ctx.quick {
        return Ok(());
    }
    // Real footage.
    let (Some(candle), campfire) = (
        crate::demo::shared_data("candle.mp4"),
        crate::demo::shared_data("campfire.mp4"),
    ) else {
        ctx.global
            .say("  (../shared/data not found: skipping the footage scenario)");
        return Ok(());
    };
    let campfire = campfire.filter(|_| ignis_media::ffmpeg_available());
    let real = ctx.path("eigen/footage.db")?;
    let mut argv: Vec<String> = vec!["train".into(), candle.to_string_lossy().into_owned()];
    if let Some(cf) = &campfire {
        argv.push(cf.to_string_lossy().into_owned());
    }
    // The default framing: the clips at their own resolution in a common frame that holds
    // them all (candle 480x480 and campfire 960x540: 960x540), so the scenario is written
    // at that size, database frames read from the source videos (§7.1.2, no stored
    // frames). Every second frame keeps the training short.
    argv.extend(["--stride", "2", "-o"].map(String::from));
    argv.push(real.to_string_lossy().into_owned());
    let a = crate::parse_sub::<crate::eigen::TrainArgs>(
        &argv.iter().map(String::as_str).collect::<Vec<_>>(),
    )?;
    crate::eigen::train(a, &Global { quiet: true }).context("training the footage database")?;
    let fdb = EigenfireDb::open(&real)?;
    let cn = fdb.clips()[0].name.clone();
    let mut motions = vec![
        ("calm", cn.as_str(), 100, 300),
        ("later", cn.as_str(), 400, 700),
    ];
    let mut seq = vec!["calm", "later"];
    let mut methods = vec!["end-growing", "direct"];
    let cf_name = fdb.clips().get(1).map(|c| c.name.clone());
    if let Some(cf) = &cf_name {
        motions.push(("camp", cf.as_str(), 0, 240));
        seq.push("camp");
        // Candle into campfire: Direct Bridging finds no frames between two so different
        // flames and plays a cut; `auto` measures it against the other methods and the
        // morph on the rendered frames and keeps the smoothest (the synthetic scenario
        // above shows every method).
        methods = vec!["end-growing", "auto", "low-pass"];
    }
    let methods = workable(&fdb, &motions, &seq, &methods)?;
    for (mode, extra) in [
        ("original", "[colour]\nmode = \"original\"\n"),
        ("synthetic", "[colour]\nmode = \"synthetic\"\n"),
    ] {
        let rel = format!("eigen/footage-{mode}.toml");
        let reals = relative_to_scenario(&real, &ctx.path(&rel)?);
        write_scenario(
            ctx,
            &rel,
            &demo_scenario(&reals, &motions, &seq, &methods, extra),
        )?;
        demo_render(
            ctx,
            &rel,
            &format!("eigen/footage-{mode}.mp4"),
            &format!(
                "candle.mp4{} joined and looped, {mode} colouring",
                if cf_name.is_some() {
                    " + campfire.mp4"
                } else {
                    ""
                }
            ),
        )?;
    }
    Ok(())
}

/// A scenario's default look: original colouring, bloom, alpha matte, §7.1.2 frames.
pub fn default_look() -> ignis_eigen::scenario::Look {
    ignis_eigen::scenario::Look {
        mode: ignis_eigen::scenario::ColourMode::Original,
        tint: ignis_core::colour::Tint::Solid([1.0, 0.42, 0.08]),
        tint_from_footage: true,
        threshold: ignis_eigen::colour::THESIS_THRESHOLD,
        bloom: Some(ignis_core::post::BloomParams::default()),
        smoke: None,
        matte: true,
        fast_path: true,
        originals: Default::default(),
        masks: Default::default(),
        mask_mode: ignis_eigen::colour::MaskMode::Add,
    }
}

/// `ignis bench eigen-animate`'s footage case: a loop of 120 database frames of a 1080p
/// clip (Ignis's synthetic campfire written as MP4, trained with the default settings)
/// rendered with original colouring, bloom and the alpha matte, reading the source video
/// (decode included; encoding the output is not: frames are dropped). `quick`: 480x270,
/// 30 frames. `keep`: a directory where the clip and its database are kept and reused
/// by later runs (`train_s` is then 0).
pub fn bench_footage(quick: bool, keep: Option<&std::path::Path>) -> Result<serde_json::Value> {
    use std::time::Instant;
    let (size, frames, loop_len) = if quick {
        (
            Size {
                width: 480,
                height: 270,
            },
            36,
            30,
        )
    } else {
        (
            Size {
                width: 1920,
                height: 1080,
            },
            128,
            120,
        )
    };
    // without `keep`, a new temporary directory (removed on return, an error's too)
    let temp;
    let dir = match keep {
        Some(k) => k.join(if quick { "footage-quick" } else { "footage" }),
        None => {
            temp = tempfile::Builder::new()
                .prefix("ignis-bench-footage-")
                .tempdir()
                .context("creating a temporary directory for the clip")?;
            temp.path().to_path_buf()
        }
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let clip = dir.join("fire.mp4");
    let dbp = dir.join("fire.db");
    let reuse = keep.is_some() && clip.is_file() && dbp.join("manifest.json").is_file();
    let t_train = Instant::now();
    if !reuse {
        train_footage_case(&clip, &dbp, size, frames)?;
    }
    let train_s = t_train.elapsed().as_secs_f64();
    let db = EigenfireDb::open(&dbp)?;
    let (mut plan, _) = render::loop_plan(
        &db,
        "fire",
        4..4 + loop_len,
        ignis_eigen::transition::Transition::Auto,
        db.manifest().e_render,
        0,
    )?;
    // The case is about database frames: the range itself, every frame from the footage.
    plan.frames
        .retain(|f| matches!(f.source, ignis_eigen::transition::FrameRef::Db(_)));
    let look = default_look();
    let mut n = 0usize;
    let t = Instant::now();
    render::render_plan_with(
        &db,
        &plan,
        &look,
        &render::RenderOptions::default(),
        &mut MediaSources::default(),
        &mut |f| {
            n += (f.width() == size.width) as usize;
            Ok(())
        },
        &mut |_| {},
    )?;
    let s = t.elapsed().as_secs_f64();
    let fps = n as f64 / s;
    Ok(serde_json::json!({
        "case": format!("{size} loop of {n} database frames, original colouring + bloom + alpha, reading the source MP4 (decode included)"),
        "frames": n,
        "seconds": s,
        "frames_per_s": fps,
        "goal": if quick { "judged at full size (1920x1080)".to_string() } else { ">= 60 frames/s".to_string() },
        "met": !quick && fps >= 60.0,
        "train_s": train_s,
        "threads": rayon::current_num_threads(),
    }))
}

/// [`bench_footage`]'s clip (Ignis's synthetic campfire, `frames` frames of `size`,
/// written as MP4 to `clip`) and its database at `dbp` (default settings).
fn train_footage_case(
    clip: &std::path::Path,
    dbp: &std::path::Path,
    size: Size,
    frames: usize,
) -> Result<()> {
    use ignis_eigen::train::{ClipInput, ClipSpec, NoProgress, TrainParams};
    let sp = ignis_eigen::synthetic::SyntheticParams {
        size,
        frames,
        style: ignis_eigen::synthetic::FlameStyle::Campfire,
        seed: 5,
    };
    let mut w = ignis_media::create(clip, size, &ignis_media::WriteOptions::default())?;
    for t in 0..frames {
        w.push(&ignis_eigen::synthetic::synthetic_frame(&sp, t)?)?;
    }
    w.finish()?;
    let mut spec = ClipSpec::new("fire");
    spec.path = Some(clip.to_path_buf());
    let input = ClipInput::new(spec, ignis_eigen::MediaFootage::open(clip)?);
    let tp = TrainParams {
        pack_size: 64,
        ..Default::default()
    };
    ignis_eigen::train(
        std::slice::from_ref(&input),
        &ignis_eigen::PreprocessParams::default(),
        &tp,
        dbp,
        &mut NoProgress,
    )?;
    Ok(())
}
