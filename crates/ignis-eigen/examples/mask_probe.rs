//! Writes, for chosen frames of a clip, a side-by-side PNG: the frame (sRGB), then the
//! frame with the default isolated mask (green) and the bright core (linear grey >= 0.8,
//! red outline of the 10-px dilation). Usage: mask_probe CLIP OUTDIR FRAME...
use ignis_core::palette::linear_to_srgb;
use ignis_eigen::preprocess::frame_mask;
use ignis_eigen::PreprocessParams;
use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let (clip, out) = (Path::new(&a[1]), Path::new(&a[2]));
    let want: Vec<usize> = a[3..].iter().map(|s| s.parse().unwrap()).collect();
    let end = want.iter().max().unwrap() + 1;
    let opts = ignis_media::ReadOptions {
        range: Some(ignis_media::FrameRange::frames(0, Some(end as u64))),
        ..Default::default()
    };
    let p = PreprocessParams::default();
    std::fs::create_dir_all(out).unwrap();
    for (i, f) in ignis_media::open(clip, &opts).unwrap().enumerate() {
        if !want.contains(&i) {
            continue;
        }
        let f = f.unwrap();
        let (w, h) = (f.width(), f.height());
        let lum = f.luminance();
        let core = image::GrayImage::from_fn(w, h, |x, y| {
            image::Luma([if lum.get(x, y) >= 0.8 { 255 } else { 0 }])
        });
        let dil = imageproc::morphology::dilate(&core, imageproc::distance_transform::Norm::L2, 10);
        let m = frame_mask(&f, &p, true).mask;
        let l8 = ignis_eigen::mask::luma8(&f);
        if let Some(lv) = ignis_eigen::mask::isolate_levels(
            &l8,
            w,
            h,
            p.mask.isolate_floor,
            p.mask.isolate_edge_tolerance,
        ) {
            let mut s = format!(
                "frame {i}: vmax {} merge {} chosen {}\n",
                lv.vmax, lv.merge, lv.chosen
            );
            for t in (70..=lv.vmax).rev().step_by(5) {
                s.push_str(&format!(
                    "  {t}: area {} edge {:.1}\n",
                    lv.area[t], lv.edge[t]
                ));
            }
            eprint!("{s}");
        }
        let mut img = image::RgbImage::new(w * 2, h);
        for y in 0..h {
            for x in 0..w {
                let px = f.get(x, y);
                let s = [0, 1, 2].map(|c| (linear_to_srgb(px[c].clamp(0.0, 1.0)) * 255.0) as u8);
                img.put_pixel(x, y, image::Rgb(s));
                let mut o = s.map(|v| v / 2);
                if m.get_pixel(x, y)[0] > 0 {
                    o[1] = o[1].saturating_add(110);
                }
                let edge = dil.get_pixel(x, y)[0] > 0
                    && [(1i32, 0i32), (-1, 0), (0, 1), (0, -1)]
                        .iter()
                        .any(|(dx, dy)| {
                            let (xx, yy) = (x as i32 + dx, y as i32 + dy);
                            xx < 0
                                || yy < 0
                                || xx >= w as i32
                                || yy >= h as i32
                                || dil.get_pixel(xx as u32, yy as u32)[0] == 0
                        });
                if edge || core.get_pixel(x, y)[0] > 0 && (x + y) % 4 == 0 {
                    o = [255, 0, 0];
                }
                img.put_pixel(w + x, y, image::Rgb(o));
            }
        }
        img.save(out.join(format!("{i:04}.png"))).unwrap();
        eprintln!("frame {i}");
    }
}
