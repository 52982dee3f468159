//! The post pipeline of a rendered frame: bloom, then straight alpha.

use crate::error::Result;
use ignis_core::post::{bloom_rgba, BloomParams};
use ignis_core::RgbaFrame;
use rayon::prelude::*;

/// The post pipeline: bloom on the premultiplied HDR frame (skipped when
/// `bloom.passes == 0`), then conversion to straight alpha with
/// `a' = clamp(max(a, max(r, g, b)), 0, 1)` and `rgb' = rgb / a'` — so compositing the
/// result "over" a background adds the fire's light to it where it is faint.
pub fn finish(premultiplied: &RgbaFrame, bloom: &BloomParams) -> Result<RgbaFrame> {
    let straight = |p: &[f32; 4]| {
        let a = p[3].max(p[0]).max(p[1]).max(p[2]).clamp(0.0, 1.0);
        if a > 0.0 {
            [p[0] / a, p[1] / a, p[2] / a, a]
        } else {
            [0.0; 4]
        }
    };
    const CHUNK: usize = 4096;
    if bloom.passes > 0 {
        let mut f = bloom_rgba(premultiplied, bloom)?;
        f.data_mut()
            .par_chunks_mut(CHUNK)
            .for_each(|c| c.iter_mut().for_each(|p| *p = straight(p)));
        Ok(f)
    } else {
        let data = premultiplied
            .data()
            .par_iter()
            .with_min_len(CHUNK)
            .map(straight)
            .collect();
        Ok(RgbaFrame::from_vec(premultiplied.size(), data)?)
    }
}
