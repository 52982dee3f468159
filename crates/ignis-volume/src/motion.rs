//! Macro motion: scripted control-point keyframes or a particle simulation, and
//! bi-directional collision with spheres and planes.
//!
//! Source: fuller-procedural-volumetric-fire.txt §3, eq. (7)–(8) (after Lamorlette & Foster
//! 2002). Particles are emitted at the fire's base at a fixed rate; each moves with
//!
//! `dx/dt = v + w(x, t) + d(T) + c(T, age)`, `c = −β g (T₀ − T) age² · ẑ`, `β = 1/T`,
//!
//! where `v` is the fire's velocity (source velocity plus the initial rise speed), `w` a
//! wind field (a constant wind modulated by 3-D Improved Perlin gusts), `d(T)` a
//! per-particle random dispersion proportional to the particle's excess temperature, and
//! `T` cools exponentially towards `T₀`. Control point `i` of the centre curve is the point
//! of the particle stream whose age is `i/(n−1)` of the fire's lifetime (interpolated
//! between the two nearest particles), so the curve moves smoothly as particles are born.
//!
//! Departure: the paper does not give `g`'s units in world space; [`SimParams::buoyancy`]
//! scales eq. (8) to the scene.
//!
//! Collisions: particles (and, for scripts, control points) that enter an obstacle are
//! projected back onto its surface and lose their velocity into it — the fire is deflected —
//! and every contact is reported as a [`Collision`] (where, the surface normal, how strong).

use crate::error::{Result, VolumeError};
use crate::lattice::{add, dot, norm, normalize, scale, sub, V3};
use crate::noise::perlin3;
use ignis_core::Rng;
use serde::{Deserialize, Serialize};

/// A solid the fire cannot enter.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Obstacle {
    /// A ball of `radius` around `centre`.
    Sphere { centre: [f32; 3], radius: f32 },
    /// The half-space behind a plane through `point`; the fire stays on the side `normal`
    /// points to.
    Plane { point: [f32; 3], normal: [f32; 3] },
}

impl Obstacle {
    /// Checks sizes and normals; `field` names the obstacle in error messages.
    pub fn validate(&self, field: &str) -> Result<()> {
        match *self {
            Obstacle::Sphere { centre, radius } => {
                if !(radius > 0.0 && radius <= 1e6)
                    || centre.iter().any(|v| !(v.is_finite() && v.abs() <= 1e6))
                {
                    return Err(VolumeError::bad(
                        format!("{field}.radius"),
                        "the radius must be in (0, 1e6] and the centre within ±1e6 world units",
                    ));
                }
            }
            Obstacle::Plane { point, normal } => {
                if point.iter().any(|v| !v.is_finite()) || normalize(normal).is_none() {
                    return Err(VolumeError::bad(
                        format!("{field}.normal"),
                        "must be a non-zero finite vector",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Signed distance (negative inside) and outward unit normal at `p`.
    pub fn distance(&self, p: V3) -> (f32, V3) {
        match *self {
            Obstacle::Sphere { centre, radius } => {
                let d = sub(p, centre);
                let l = norm(d);
                let n = normalize(d).unwrap_or([0.0, 0.0, 1.0]);
                (l - radius, n)
            }
            Obstacle::Plane { point, normal } => {
                let n = normalize(normal).unwrap_or([0.0, 0.0, 1.0]);
                (dot(sub(p, point), n), n)
            }
        }
    }
}

/// One contact between a fire and an obstacle, reported to the caller.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Collision {
    /// Index of the fire in the scene.
    pub fire: usize,
    /// Index of the obstacle in the scene.
    pub obstacle: usize,
    /// Contact point on the obstacle's surface (world units).
    pub point: [f32; 3],
    /// Outward surface normal there.
    pub normal: [f32; 3],
    /// How strong: the speed (units/s) with which the fire pushed into the surface.
    pub strength: f32,
}

/// Pushes `p` out of every obstacle; returns the contacts.
fn resolve(
    p: &mut V3,
    vel: Option<&mut V3>,
    obstacles: &[Obstacle],
    fire: usize,
    dt: f32,
    out: &mut Vec<Collision>,
) {
    let mut vel = vel;
    for (oi, o) in obstacles.iter().enumerate() {
        let (d, n) = o.distance(*p);
        if d < 0.0 {
            *p = sub(*p, scale(n, d));
            let mut strength = -d / dt.max(1e-6);
            if let Some(v) = vel.as_deref_mut() {
                let vn = dot(*v, n);
                if vn < 0.0 {
                    *v = sub(*v, scale(n, vn));
                    strength = strength.max(-vn);
                }
            }
            out.push(Collision {
                fire,
                obstacle: oi,
                point: *p,
                normal: n,
                strength,
            });
        }
    }
}

/// A scripted key pose of the control points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Time in seconds.
    pub time: f32,
    /// Control points `[x, y, z, radius]`.
    pub points: Vec<[f32; 4]>,
}

/// A pre-scripted sequence of control-point keyframes, interpolated with smoothstep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Script {
    pub keyframes: Vec<Keyframe>,
    /// Repeat after the last keyframe (default true).
    #[serde(default = "yes")]
    pub looped: bool,
}

fn yes() -> bool {
    true
}

impl Script {
    /// Checks that keyframes exist, share one point count and have increasing times.
    pub fn validate(&self, field: &str) -> Result<()> {
        let Some(first) = self.keyframes.first() else {
            return Err(VolumeError::bad(
                format!("{field}.keyframes"),
                "needs at least one keyframe",
            ));
        };
        for (i, k) in self.keyframes.iter().enumerate() {
            if k.points.len() != first.points.len() {
                return Err(VolumeError::bad(
                    format!("{field}.keyframes[{i}].points"),
                    format!(
                        "{} points; every keyframe needs {}",
                        k.points.len(),
                        first.points.len()
                    ),
                ));
            }
            if i > 0 && (k.time.is_nan() || k.time <= self.keyframes[i - 1].time) {
                return Err(VolumeError::bad(
                    format!("{field}.keyframes[{i}].time"),
                    "times must increase",
                ));
            }
        }
        Ok(())
    }

    /// Control points at `time` seconds.
    pub fn at(&self, time: f32) -> Vec<[f32; 4]> {
        let k = &self.keyframes;
        if k.len() == 1 {
            return k[0].points.clone();
        }
        let (t0, t1) = (k[0].time, k[k.len() - 1].time);
        let mut t = time;
        if self.looped && t1 > t0 {
            t = t0 + (time - t0).rem_euclid(t1 - t0);
        }
        if t <= t0 {
            return k[0].points.clone();
        }
        if t >= t1 {
            return k[k.len() - 1].points.clone();
        }
        let i = k.partition_point(|f| f.time <= t).clamp(1, k.len() - 1);
        let (a, b) = (&k[i - 1], &k[i]);
        let f = (t - a.time) / (b.time - a.time);
        let f = f * f * (3.0 - 2.0 * f);
        a.points
            .iter()
            .zip(&b.points)
            .map(|(p, q)| [0, 1, 2, 3].map(|c| p[c] + f * (q[c] - p[c])))
            .collect()
    }

    /// Control points at `time`, pushed out of `obstacles` (keeping a clearance of each
    /// point's radius), with the contacts.
    pub fn at_with_collisions(
        &self,
        time: f32,
        dt: f32,
        obstacles: &[Obstacle],
        fire: usize,
    ) -> (Vec<[f32; 4]>, Vec<Collision>) {
        let mut pts = self.at(time);
        let mut hits = Vec::new();
        deflect_points(&mut pts, dt, obstacles, fire, &mut hits);
        (pts, hits)
    }
}

/// Pushes control points out of obstacles keeping a clearance of their radius.
pub(crate) fn deflect_points(
    pts: &mut [[f32; 4]],
    dt: f32,
    obstacles: &[Obstacle],
    fire: usize,
    hits: &mut Vec<Collision>,
) {
    for p in pts.iter_mut() {
        let r = p[3];
        for (oi, o) in obstacles.iter().enumerate() {
            let (d, n) = o.distance([p[0], p[1], p[2]]);
            if d < r {
                let q = add([p[0], p[1], p[2]], scale(n, r - d));
                *p = [q[0], q[1], q[2], p[3]];
                let contact = sub(q, scale(n, r));
                hits.push(Collision {
                    fire,
                    obstacle: oi,
                    point: contact,
                    normal: n,
                    strength: (r - d) / dt.max(1e-6),
                });
            }
        }
    }
}

/// Settings of the particle simulation (eq. 7–8). Units: world units, seconds, kelvin.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimParams {
    /// Where particles are born (the fire's base). Default origin.
    pub source: [f32; 3],
    /// The fire's own velocity `v`, added to every particle. Default 0.
    pub velocity: [f32; 3],
    /// Initial upward speed of a new particle. Default 1.0.
    pub rise_speed: f32,
    /// Temperature at birth, K (> ambient). Default 1500.
    pub temperature: f32,
    /// Ambient temperature `T₀`, K. Default 300.
    pub ambient: f32,
    /// Cooling rate towards `T₀`, 1/s. Default 1.0.
    pub cooling: f32,
    /// Gravitational constant `g`. Default 9.81.
    pub gravity: f32,
    /// Scale of the buoyancy term (eq. 8) in world units. Default 0.3.
    pub buoyancy: f32,
    /// Constant wind velocity. Default 0.
    pub wind: [f32; 3],
    /// Relative strength of the wind's gusts (Perlin noise in position and time), 0–2.
    /// Default 0.3.
    pub gust: f32,
    /// Dispersion speed of a particle at birth temperature, units/s. Default 0.15.
    pub dispersion: f32,
    /// Age of the fire's tip, seconds (> 0). Default 1.2.
    pub lifetime: f32,
    /// Number of control points of the centre curve (≥ degree + 1). Default 6.
    pub control_points: usize,
    /// Radius at the base and at the tip (linear in between). Default 1.0 and 0.5.
    pub radius: f32,
    pub tip_radius: f32,
    /// Integration steps per frame, 1–64. Default 4. A step (`1 / (fps · substeps)` s) may
    /// not be longer than `lifetime`: the scene refuses it, naming the substeps that fit.
    pub substeps: usize,
}

impl Default for SimParams {
    fn default() -> Self {
        SimParams {
            source: [0.0; 3],
            velocity: [0.0; 3],
            rise_speed: 1.0,
            temperature: 1500.0,
            ambient: 300.0,
            cooling: 1.0,
            gravity: 9.81,
            buoyancy: 0.3,
            wind: [0.0; 3],
            gust: 0.3,
            dispersion: 0.15,
            lifetime: 1.2,
            control_points: 6,
            radius: 1.0,
            tip_radius: 0.5,
            substeps: 4,
        }
    }
}

impl SimParams {
    /// Checks every field; `field` prefixes error names (e.g. `fire[0].simulation`).
    pub fn validate(&self, field: &str, degree: usize) -> Result<()> {
        let f = |n: &str| format!("{field}.{n}");
        let finite3 = |v: [f32; 3]| v.iter().all(|x| x.is_finite());
        if !finite3(self.source) {
            return Err(VolumeError::bad(f("source"), "must be finite"));
        }
        if !finite3(self.velocity) || !finite3(self.wind) {
            return Err(VolumeError::bad(f("wind"), "velocities must be finite"));
        }
        if !(self.ambient > 0.0 && self.temperature > 0.0 && self.temperature.is_finite()) {
            return Err(VolumeError::bad(
                f("temperature"),
                "temperatures must be positive kelvin",
            ));
        }
        if !(self.lifetime >= 1e-3 && self.lifetime <= 60.0) {
            return Err(VolumeError::bad(
                f("lifetime"),
                format!(
                    "{} s; use 0.001 to 60 (shorter lifetimes emit particles without bound)",
                    self.lifetime
                ),
            ));
        }
        if self.control_points < degree + 1 || self.control_points > 64 {
            return Err(VolumeError::bad(
                f("control_points"),
                format!(
                    "{}; need degree + 1 = {} to 64",
                    self.control_points,
                    degree + 1
                ),
            ));
        }
        let max_r = crate::spline::MAX_RADIUS;
        if !((0.0..=max_r).contains(&self.radius) && (0.0..=max_r).contains(&self.tip_radius)) {
            return Err(VolumeError::bad(
                f("radius"),
                format!(
                    "radius {} and tip_radius {}: each must be in 0..={max_r:e} world units",
                    self.radius, self.tip_radius
                ),
            ));
        }
        if !(1..=64).contains(&self.substeps) {
            return Err(VolumeError::bad(f("substeps"), "use 1 to 64"));
        }
        for (n, v) in [
            ("rise_speed", self.rise_speed),
            ("cooling", self.cooling),
            ("gravity", self.gravity),
            ("buoyancy", self.buoyancy),
            ("gust", self.gust),
            ("dispersion", self.dispersion),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(VolumeError::bad(f(n), "must be a finite number ≥ 0"));
            }
        }
        Ok(())
    }
}

#[derive(Clone, Debug)]
struct Particle {
    pos: V3,
    vel: V3,
    age: f32,
    /// Unit dispersion direction, fixed at birth.
    dir: V3,
}

/// The particle simulation driving one fire's control points.
#[derive(Clone, Debug)]
pub struct ParticleSim {
    p: SimParams,
    seed: u64,
    /// Youngest first.
    particles: std::collections::VecDeque<Particle>,
    born: u64,
    time: f32,
    since_emit: f32,
    emit_interval: f32,
}

impl ParticleSim {
    /// A simulation warmed up for one lifetime so the fire is fully grown at time 0.
    pub fn new(params: SimParams, seed: u64, obstacles: &[Obstacle]) -> ParticleSim {
        let n = params.control_points.max(2);
        let emit_interval = params.lifetime / ((n - 1) * 3) as f32;
        let mut sim = ParticleSim {
            p: params,
            seed,
            particles: Default::default(),
            born: 0,
            time: 0.0,
            since_emit: 0.0,
            emit_interval,
        };
        sim.emit();
        let warm = sim.p.lifetime * 1.05;
        let steps = (warm / (1.0 / 120.0)).ceil() as usize;
        let mut sink = Vec::new();
        for _ in 0..steps {
            sim.step(warm / steps as f32, obstacles, 0, &mut sink);
        }
        sim.time = 0.0;
        sim
    }

    fn emit(&mut self) {
        let mut rng = Rng::derive(self.seed, self.born);
        let th = rng.uniform(0.0, std::f64::consts::TAU) as f32;
        let z = rng.uniform(-0.3, 0.3) as f32;
        let h = (1.0 - z * z).sqrt();
        self.born += 1;
        self.particles.push_front(Particle {
            pos: self.p.source,
            vel: [0.0; 3],
            age: 0.0,
            dir: [h * th.cos(), h * th.sin(), z],
        });
    }

    /// Temperature of a particle of `age` seconds (exponential cooling towards `T₀`).
    pub fn temperature(&self, age: f32) -> f32 {
        let p = &self.p;
        p.ambient + (p.temperature - p.ambient) * (-p.cooling * age).exp()
    }

    /// Buoyancy velocity of eq. (8), upward component: `−β g (T₀ − T) age²` with `β = 1/T`,
    /// scaled by [`SimParams::buoyancy`].
    pub fn buoyancy(&self, temperature: f32, age: f32) -> f32 {
        let p = &self.p;
        -(1.0 / temperature) * p.gravity * (p.ambient - temperature) * age * age * p.buoyancy
    }

    /// Wind `w(x, t)`: the constant wind modulated by Perlin gusts.
    pub fn wind(&self, x: V3, t: f32) -> V3 {
        let g = 1.0 + self.p.gust * perlin3(x[0] * 0.5 + 17.0, x[2] * 0.5 + 3.0, t * 0.7 + 0.5);
        scale(self.p.wind, g)
    }

    /// Advances by `dt` seconds; contacts are appended to `hits`.
    pub fn step(
        &mut self,
        dt: f32,
        obstacles: &[Obstacle],
        fire: usize,
        hits: &mut Vec<Collision>,
    ) {
        self.since_emit += dt;
        while self.since_emit >= self.emit_interval {
            self.since_emit -= self.emit_interval;
            self.emit();
        }
        let t = self.time;
        let base = add(self.p.velocity, [0.0, 0.0, self.p.rise_speed]);
        let t_range = (self.p.temperature - self.p.ambient).abs().max(1e-6);
        let mut parts = std::mem::take(&mut self.particles);
        for q in parts.iter_mut() {
            let temp = self.temperature(q.age);
            let w = self.wind(q.pos, t);
            let d = scale(q.dir, self.p.dispersion * (temp - self.p.ambient) / t_range);
            let c = [0.0, 0.0, self.buoyancy(temp, q.age)];
            let v = add(add(base, w), add(d, c));
            q.vel = v;
            q.pos = add(q.pos, scale(v, dt));
            q.age += dt;
            resolve(&mut q.pos, Some(&mut q.vel), obstacles, fire, dt, hits);
        }
        let max_age = self.p.lifetime + 2.0 * self.emit_interval;
        while parts.back().is_some_and(|q| q.age > max_age) {
            parts.pop_back();
        }
        self.particles = parts;
        self.time += dt;
    }

    /// Advances one frame of `frame_dt` seconds in [`SimParams::substeps`] steps.
    pub fn advance(
        &mut self,
        frame_dt: f32,
        obstacles: &[Obstacle],
        fire: usize,
    ) -> Vec<Collision> {
        let mut hits = Vec::new();
        let n = self.p.substeps.max(1);
        for _ in 0..n {
            self.step(frame_dt / n as f32, obstacles, fire, &mut hits);
        }
        hits
    }

    /// Positions of all live particles, youngest first.
    pub fn particles(&self) -> Vec<[f32; 3]> {
        self.particles.iter().map(|q| q.pos).collect()
    }

    /// The centre curve's control points `[x, y, z, r]`: point `i` is where the particle
    /// stream's age equals `i/(n−1)` of the lifetime.
    pub fn control_points(&self) -> Vec<[f32; 4]> {
        let n = self.p.control_points.max(2);
        let parts: Vec<(f32, V3)> = std::iter::once((0.0, self.p.source))
            .chain(self.particles.iter().map(|q| (q.age, q.pos)))
            .collect();
        (0..n)
            .map(|i| {
                let f = i as f32 / (n - 1) as f32;
                let age = f * self.p.lifetime;
                let k = parts.partition_point(|(a, _)| *a < age);
                let pos = if k == 0 {
                    parts[0].1
                } else if k >= parts.len() {
                    parts[parts.len() - 1].1
                } else {
                    let (a0, p0) = parts[k - 1];
                    let (a1, p1) = parts[k];
                    let w = if a1 > a0 { (age - a0) / (a1 - a0) } else { 0.0 };
                    add(p0, scale(sub(p1, p0), w))
                };
                let r = self.p.radius + f * (self.p.tip_radius - self.p.radius);
                [pos[0], pos[1], pos[2], r]
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn calm() -> SimParams {
        SimParams {
            gust: 0.0,
            dispersion: 0.0,
            ..Default::default()
        }
    }

    #[test]
    fn buoyancy_lifts_hot_and_sinks_cold() {
        let sim = ParticleSim::new(calm(), 1, &[]);
        assert!(sim.buoyancy(1200.0, 0.5) > 0.0);
        assert!(sim.buoyancy(250.0, 0.5) < 0.0);
        assert_eq!(sim.buoyancy(300.0, 0.5), 0.0);
        // with no rise speed, particles still go up, faster when hotter
        let hot = ParticleSim::new(
            SimParams {
                rise_speed: 0.0,
                ..calm()
            },
            1,
            &[],
        );
        let cool = ParticleSim::new(
            SimParams {
                rise_speed: 0.0,
                temperature: 400.0,
                ..calm()
            },
            1,
            &[],
        );
        let top = |s: &ParticleSim| s.control_points().last().unwrap()[2];
        assert!(top(&hot) > 0.05, "{}", top(&hot));
        assert!(top(&hot) > top(&cool));
    }

    #[test]
    fn wind_bends_fire_downwind() {
        let mut sim = ParticleSim::new(
            SimParams {
                wind: [1.5, 0.0, 0.0],
                ..calm()
            },
            2,
            &[],
        );
        for _ in 0..30 {
            sim.advance(1.0 / 30.0, &[], 0);
        }
        let cp = sim.control_points();
        assert_eq!(cp[0][0], 0.0);
        assert!(cp.last().unwrap()[0] > 0.5, "{cp:?}");
        assert!(cp.windows(2).all(|w| w[1][0] >= w[0][0] - 1e-6));
    }

    #[test]
    fn collision_plane_is_never_crossed_and_is_reported() {
        // a ceiling at z = 1, slightly tilted, facing down
        let plane = Obstacle::Plane {
            point: [0.0, 0.0, 1.0],
            normal: [0.2, 0.0, -1.0],
        };
        let n = normalize([0.2, 0.0, -1.0]).unwrap();
        let obs = [plane];
        let mut sim = ParticleSim::new(
            SimParams {
                wind: [0.3, 0.2, 0.0],
                ..Default::default()
            },
            3,
            &obs,
        );
        let mut reported = 0;
        for _ in 0..90 {
            reported += sim.advance(1.0 / 30.0, &obs, 0).len();
            for p in sim.particles() {
                assert!(dot(sub(p, [0.0, 0.0, 1.0]), n) >= -1e-5, "{p:?}");
            }
            for c in sim.control_points() {
                assert!(dot(sub([c[0], c[1], c[2]], [0.0, 0.0, 1.0]), n) >= -1e-5);
            }
        }
        assert!(reported > 0);
    }

    #[test]
    fn script_interpolates_and_loops() {
        let s = Script {
            keyframes: vec![
                Keyframe {
                    time: 0.0,
                    points: vec![[0.0, 0.0, 0.0, 1.0]; 4],
                },
                Keyframe {
                    time: 1.0,
                    points: vec![[1.0, 0.0, 0.0, 1.0]; 4],
                },
            ],
            looped: true,
        };
        s.validate("fire[0].script").unwrap();
        assert!((s.at(0.5)[0][0] - 0.5).abs() < 1e-6);
        assert!((s.at(1.5)[0][0] - 0.5).abs() < 1e-6);
        let sphere = Obstacle::Sphere {
            centre: [0.5, 0.0, 0.0],
            radius: 0.5,
        };
        let (pts, hits) = s.at_with_collisions(0.5, 1.0 / 30.0, &[sphere], 0);
        assert!(!hits.is_empty());
        assert!(sphere.distance([pts[0][0], pts[0][1], pts[0][2]]).0 >= 1.0 - 1e-4);
    }
}
