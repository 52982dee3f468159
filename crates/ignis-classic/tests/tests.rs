//! Integration tests of the classic fire: golden images, properties, thread independence.

use ignis_classic::{ClassicFire, ClassicParams, Kernel, SourceEdge, SourceMode, Sparkle};
use ignis_core::Size;
use proptest::prelude::*;

fn run(params: &ClassicParams, frames: usize, par: bool) -> ClassicFire {
    let mut f = ClassicFire::new(params.clone()).unwrap();
    for _ in 0..frames {
        if par {
            f.step_par()
        } else {
            f.step()
        }
    }
    f
}

mod golden {
    use super::*;
    use std::path::PathBuf;

    /// Compares the 8-bit buffer exactly against `tests/golden/<name>`; a missing golden is
    /// written and the test fails; `UPDATE_GOLDEN=1` regenerates.
    fn check(name: &str, fire: &ClassicFire) {
        let p = fire.params();
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
        let path = dir.join(name);
        let img = image::GrayImage::from_raw(p.size.width, p.size.height, fire.buffer().to_vec())
            .unwrap();
        if std::env::var_os("UPDATE_GOLDEN").is_some() || !path.exists() {
            std::fs::create_dir_all(&dir).unwrap();
            img.save(&path).unwrap();
            if std::env::var_os("UPDATE_GOLDEN").is_none() {
                panic!("golden {name} was missing and has been written; check it and re-run");
            }
        }
        let golden = image::open(&path).unwrap().to_luma8();
        assert_eq!(golden.dimensions(), img.dimensions());
        let diff = golden
            .as_raw()
            .iter()
            .zip(img.as_raw())
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(diff, 0, "{diff} pixels differ from {name}");
    }

    #[test]
    fn classic_64x48_fade3_seed7() {
        let p = ClassicParams {
            size: Size::new(64, 48).unwrap(),
            fade: 3,
            seed: 7,
            ..Default::default()
        };
        check("classic-64x48-fade3-seed7.png", &run(&p, 40, false));
    }

    #[test]
    fn classic_64x48_fade1_perlin_buffered_seed7() {
        let p = ClassicParams {
            size: Size::new(64, 48).unwrap(),
            fade: 1,
            seed: 7,
            source: SourceMode::Perlin {
                scale: 16.0,
                speed: 0.1,
            },
            kernel: Kernel::Buffered,
            sparkle: None,
            ..Default::default()
        };
        check(
            "classic-64x48-fade1-perlin-buffered-seed7.png",
            &run(&p, 40, false),
        );
    }
}

mod properties {
    use super::*;

    #[test]
    fn fade_255_blanks_everything_above_the_source_line_in_one_frame() {
        for kernel in [Kernel::Article, Kernel::Buffered] {
            let p = ClassicParams {
                size: Size::new(48, 40).unwrap(),
                fade: 255,
                sparkle: None,
                kernel,
                seed: 1,
                ..Default::default()
            };
            // warm up with a gentle fade so the buffer is full of fire, then switch to 255
            let mut f = ClassicFire::new(ClassicParams {
                fade: 1,
                ..p.clone()
            })
            .unwrap();
            for _ in 0..60 {
                f.step();
            }
            assert!(f.buffer().iter().filter(|&&v| v > 0).count() > 200);
            f.set_fade(255);
            f.step();
            let hot = f;
            let w = 48;
            let src_row = 40 - 2; // height - 1 - edge
            for (i, &v) in hot.buffer()[..src_row * w].iter().enumerate() {
                assert_eq!(v, 0, "pixel {i} above the source line is {v}");
            }
        }
    }

    #[test]
    fn same_seed_same_bytes_different_seed_different_bytes() {
        let p = ClassicParams {
            size: Size::new(40, 30).unwrap(),
            seed: 11,
            ..Default::default()
        };
        assert_eq!(run(&p, 20, false).buffer(), run(&p, 20, false).buffer());
        let q = ClassicParams {
            seed: 12,
            ..p.clone()
        };
        assert_ne!(run(&p, 20, false).buffer(), run(&q, 20, false).buffer());
    }

    #[test]
    fn top_source_mirrors_the_bottom_one() {
        let p = ClassicParams {
            size: Size::new(30, 20).unwrap(),
            seed: 5,
            ..Default::default()
        };
        let a = run(&p, 10, false).gray();
        let b = run(
            &ClassicParams {
                source_edge: SourceEdge::Top,
                ..p
            },
            10,
            false,
        )
        .gray();
        for y in 0..20 {
            assert_eq!(a.row(y), b.row(19 - y));
        }
    }

    #[test]
    fn identical_output_for_any_thread_count() {
        let p = ClassicParams {
            size: Size::new(97, 181).unwrap(),
            seed: 9,
            fade: 1,
            ..Default::default()
        };
        let reference = run(&p, 30, false);
        for kernel in [Kernel::Article, Kernel::Buffered] {
            let p = ClassicParams {
                kernel,
                ..p.clone()
            };
            let single = run(&p, 30, false);
            if kernel == Kernel::Article {
                assert_eq!(single.buffer(), reference.buffer());
            }
            for threads in [1, 2, 3, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let par = pool.install(|| run(&p, 30, true));
                assert_eq!(
                    par.buffer(),
                    single.buffer(),
                    "{kernel:?} with {threads} threads"
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn no_value_exceeds_the_source_lines_maximum(
            w in 8u32..60, h in 8u32..50, fade in 0u8..8, heat in 1u8..=255,
            seed in any::<u64>(), perlin in any::<bool>(), buffered in any::<bool>(),
            threshold in 0u8..=255, boost in 0u8..=255,
        ) {
            let p = ClassicParams {
                size: Size::new(w, h).unwrap(), fade, heat, seed,
                source: if perlin { SourceMode::Perlin { scale: 7.0, speed: 0.2 } } else { SourceMode::Random { drift: 60 } },
                kernel: if buffered { Kernel::Buffered } else { Kernel::Article },
                sparkle: Some(Sparkle { threshold, boost }),
                ..Default::default()
            };
            let mut f = ClassicFire::new(p).unwrap();
            for _ in 0..25 {
                f.step();
                let max = *f.buffer().iter().max().unwrap();
                prop_assert!(max <= heat, "value {} above heat {}", max, heat);
            }
            prop_assert_eq!(f.gray().size(), Size::new(w, h).unwrap());
        }
    }
}

/// Issue 16 §2 on short renders: the preset puffs at the law's `1.5/√D` Hz (within the
/// ±25 % of the bench; 4 s at 60 fps resolve 0.25 Hz), and its cells give a spatial
/// spectrum clearly steeper than the article's per-pixel buffer (by more than 0.7; the
/// bench measures ≈ −3.3 against ≈ −2.0, and `campfire.mp4` ≈ −3.3).
mod realism {
    use super::*;
    use ignis_core::realism::{display_luma, flicker, median_slope, reduce};
    use ignis_core::{GrayFrame, Palette};

    /// Display-luma frames of `p` at 60 fps after the CLI's 60-frame warm-up.
    fn frames(p: ClassicParams, n: usize) -> Vec<GrayFrame> {
        let palette = Palette::preset("classic").unwrap();
        let mut f = run(&p, 60, false);
        (0..n)
            .map(|_| {
                f.step();
                display_luma(&palette.apply(&f.gray()), [0.0; 3])
            })
            .collect()
    }

    #[test]
    fn preset_puffs_at_the_law_and_is_smoother_than_the_article() {
        let preset = ClassicParams {
            size: Size::new(320, 200).unwrap(),
            fps: 60.0,
            seed: 2,
            ..ClassicParams::preset()
        };
        let law = preset.puff_hz();
        assert!((law - 1.5).abs() < 1e-9);
        let lit = frames(preset.clone(), 240);
        let small: Vec<GrayFrame> = lit.iter().map(|f| reduce(f.clone(), 128)).collect();
        let fl = flicker(&small, 60.0).unwrap();
        assert!(
            (fl.hz - law).abs() <= 0.25 * law,
            "flicker {:.2} Hz vs the law {law:.2}",
            fl.hz
        );
        let pick = |v: &[GrayFrame]| -> Vec<GrayFrame> {
            (0..4).map(|k| v[30 + 50 * k].clone()).collect()
        };
        let smooth = median_slope(&pick(&lit)).unwrap();
        let article = ClassicParams {
            cell: 1,
            puff: 0.0,
            ..preset
        };
        let fine = median_slope(&pick(&frames(article, 240))).unwrap();
        assert!(
            smooth < fine - 0.7,
            "preset {smooth:.2} vs article {fine:.2}"
        );
    }
}

/// Issue 16's loop goals on the frames a looping render writes (palette `classic` over
/// black, grey 128-px metric frames of `ignis_core::loopq`): the wrap step at most 1.1× and
/// every step at most 1.2× the loop's median step, for the preset (re-timed to even
/// steps) and the article's fire (true frames), over a few seeds, sizes and lengths.
mod loops {
    use super::*;
    use ignis_core::{loopq, Palette};

    /// The loop's largest step and its wrap step over the median step, as written: settled
    /// after the CLI's 60-frame warm-up, re-timed, then `n` frames stepped and drawn.
    fn loop_steps(p: ClassicParams, n: u32) -> (f64, f64, bool) {
        let palette = Palette::preset("classic").unwrap();
        let mut f = ClassicFire::new_looping(p, n).unwrap();
        assert!(f.settle_loop(60, 4000).is_some(), "settles");
        let evened = f.even_loop_steps(&palette, [0.0; 3]);
        let frames: Vec<_> = (0..n)
            .map(|_| {
                f.step_par();
                loopq::metric_frame_rgba(&f.rgba(&palette), [0.0; 3])
            })
            .collect();
        let s = loopq::steps(&frames, true).unwrap();
        let med = loopq::median(&mut s.clone());
        let max = s.iter().copied().fold(0.0, f64::max);
        (max / med, s[s.len() - 1] / med, evened)
    }

    #[test]
    fn every_preset_loops_with_even_steps() {
        // (size, cells of the preset as the CLI picks them: 6, or side / 16 when smaller)
        for (size, cell, n) in [((96, 64), 4, 30), ((128, 96), 6, 48), ((160, 100), 6, 24)] {
            for seed in [1, 2, 3] {
                let size = Size::new(size.0, size.1).unwrap();
                let preset = ClassicParams {
                    size,
                    seed,
                    cell,
                    ..ClassicParams::preset()
                };
                let article = ClassicParams {
                    size,
                    seed,
                    ..ClassicParams::default()
                };
                for (name, p, retimed) in [("preset", preset, true), ("article", article, false)] {
                    let (max, wrap, evened) = loop_steps(p, n);
                    println!("{name} {size} N={n} seed {seed}: steps ≤ {max:.3}, wrap {wrap:.3}");
                    assert_eq!(evened, retimed, "{name} {size} N={n} seed {seed}");
                    assert!(max <= 1.2, "{name} {size} N={n} seed {seed}: step {max:.3}");
                    assert!(
                        wrap <= 1.1,
                        "{name} {size} N={n} seed {seed}: wrap {wrap:.3}"
                    );
                }
            }
        }
    }

    /// The re-timed loop is still exact and its frames depend only on their number in the
    /// loop (so any chunk of it renders the same bytes): frames `N` apart are equal and a
    /// second fire stepped straight to frame `k` shows frame `k`'s bytes.
    #[test]
    fn re_timed_loop_is_exact_and_any_frame_renders_alike() {
        let p = ClassicParams {
            size: Size::new(96, 64).unwrap(),
            seed: 5,
            cell: 4,
            ..ClassicParams::preset()
        };
        let palette = Palette::preset("classic").unwrap();
        let n = 20;
        let settled = |p: &ClassicParams| {
            let mut f = ClassicFire::new_looping(p.clone(), n).unwrap();
            f.settle_loop(60, 4000).unwrap();
            assert!(f.even_loop_steps(&palette, [0.0; 3]));
            f
        };
        let mut f = settled(&p);
        let mut first = Vec::new();
        for k in 0..2 * n {
            f.step_par();
            let bytes = f.frame_bytes();
            if k < n {
                first.push(bytes);
            } else {
                assert_eq!(bytes, first[(k - n) as usize], "frame {k}");
            }
        }
        let mut g = settled(&p);
        for _ in 0..13 {
            g.step();
        }
        assert_eq!(g.frame_bytes(), first[12]);
        // a re-timed frame is a blend, not always a kept state: some frame differs from
        // the plain loop's frame of its number
        let mut plain = ClassicFire::new_looping(p, n).unwrap();
        plain.settle_loop(60, 4000).unwrap();
        let differs = (0..n).any(|k| {
            plain.step();
            plain.frame_bytes() != first[k as usize]
        });
        assert!(differs, "the re-timing moved some frame");
    }
}
