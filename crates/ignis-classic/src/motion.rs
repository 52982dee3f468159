//! The classic fire's own motion, for motion-vector sheets: how far the picture's content
//! travels per step, derived from the update loop rather than measured on the frames.
//!
//! Every step replaces a pixel by a weighted mean of last step's pixels (minus the fade),
//! so a feature's centroid moves by the mean offset `m` of that mean's weights. The
//! buffered kernel averages itself, left, right and below equally: `m = (0, 1/4)` (a pixel
//! takes its heat from a quarter row below), content rises a quarter row per step. The
//! article's in-place loop reads the left neighbour already updated this step, itself such
//! a mean, so `m = ¼((0,0) + (1,0) + (0,1) + (−1,0) + m)`, i.e. `m = (0, 1/3)`: a third of
//! a row per step. Left and right cancel, so there is no sideways motion. With the source
//! at the top the rows are mirrored and the content falls instead.

use crate::{ClassicParams, Kernel, SourceEdge};

/// Velocity of the fire's content in buffer pixels per step, `[dx, dy]` with +y down
/// (row 0 at the top), the same everywhere in the buffer (see the module docs).
pub fn velocity_per_step(params: &ClassicParams) -> [f32; 2] {
    let rise = match params.kernel {
        Kernel::Article => 1.0 / 3.0,
        Kernel::Buffered => 0.25,
    };
    match params.source_edge {
        SourceEdge::Bottom => [0.0, -rise],
        SourceEdge::Top => [0.0, rise],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ClassicFire, Sparkle};
    use ignis_core::Size;

    /// The heat centroid of a blob started well above the source line rises by the
    /// predicted amount per step (no source line: zero heat; no fade, no sparklies).
    #[test]
    fn centroid_moves_at_the_predicted_speed() {
        for kernel in [Kernel::Article, Kernel::Buffered] {
            let params = ClassicParams {
                size: Size::new(64, 96).unwrap(),
                fade: 0,
                heat: 1,
                sparkle: None::<Sparkle>,
                kernel,
                ..Default::default()
            };
            let want = velocity_per_step(&params)[1];
            let mut fire = ClassicFire::new(params).unwrap();
            let w = fire.w;
            fire.buf.iter_mut().for_each(|v| *v = 0);
            for y in 40..50 {
                for x in 20..44 {
                    fire.buf[y * w + x] = 240;
                }
            }
            fire.top = 0;
            // Heat centroid (row) above the source line's reach.
            let centroid = |f: &ClassicFire| {
                let (mut m, mut my) = (0.0f64, 0.0f64);
                for (i, &v) in f.buf[..70 * w].iter().enumerate() {
                    m += v as f64;
                    my += v as f64 * (i / w) as f64;
                }
                (my / m) as f32
            };
            let before = centroid(&fire);
            let steps = 24;
            for _ in 0..steps {
                fire.step();
            }
            let got = (centroid(&fire) - before) / steps as f32;
            assert!(
                (got - want).abs() < 0.03,
                "{kernel:?}: {got} rows per step, want {want}"
            );
        }
    }
}
