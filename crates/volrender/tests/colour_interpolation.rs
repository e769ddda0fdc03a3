//! Density-weighted colour against hand-derived values: the colours of empty voxels never show,
//! and where every voxel has one colour both interpolations agree.

use candle_core::{Device, Tensor};
use volrender::{render, ColourInterpolation, Rays, RenderConfig, Sampler};

const GREY: [f64; 3] = [0.3, 0.3, 0.3];
const GREEN: [f64; 3] = [0.1, 0.8, 0.1];
const BACKGROUND: [f32; 3] = [1.0, 1.0, 1.0];

/// A `(4, 1, 1, 2)` volume on the default box: voxel 0 (x < 0) holds `sigma` of grey, voxel 1
/// holds `sigma1` of green.
fn two_voxels(sigma: f64, sigma1: f64) -> Tensor {
    let data = vec![
        sigma, sigma1, GREY[0], GREEN[0], GREY[1], GREEN[1], GREY[2], GREEN[2],
    ];
    Tensor::from_vec(data, (4, 1, 1, 2), &Device::Cpu).unwrap()
}

/// One ray along +x through the centres of both voxels.
fn ray() -> Rays {
    Rays::new(vec![[-3.0, 0.0, 0.0]], vec![[1.0, 0.0, 0.0]]).unwrap()
}

fn render_rgb_opacity(volume: &Tensor, interpolation: ColourInterpolation) -> ([f64; 3], f64) {
    let cfg = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 64 })
        .with_background(BACKGROUND)
        .with_opacity(true)
        .with_colour_interpolation(interpolation);
    let out = render(volume, &ray(), &cfg).unwrap();
    let rgb = out.rgb.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    let opacity = out
        .opacity
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap()[0];
    ([rgb[0], rgb[1], rgb[2]], opacity)
}

/// Every sample that weighs anything sees only the grey voxel's colour, so the pixel is exactly
/// `grey A + background (1 - A)`; interpolated separately, the empty voxel's green shows.
#[test]
fn the_colour_of_an_empty_voxel_never_shows() {
    let volume = two_voxels(2.0, 0.0);
    let (rgb, a) = render_rgb_opacity(&volume, ColourInterpolation::DensityWeighted);
    assert!(a > 0.5 && a < 1.0, "opacity {a}");
    for c in 0..3 {
        let expected = GREY[c] * a + f64::from(BACKGROUND[c]) * (1.0 - a);
        assert!(
            (rgb[c] - expected).abs() < 1e-12,
            "channel {c}: {} vs {expected}",
            rgb[c]
        );
    }
    let (separate, a_separate) = render_rgb_opacity(&volume, ColourInterpolation::Separate);
    assert_eq!(a_separate, a, "opacity does not depend on the colour rule");
    assert!(
        separate[1] - rgb[1] > 0.02 && separate[0] < rgb[0],
        "green shows when separate: {separate:?} against {rgb:?}"
    );
}

/// With one colour in every voxel, the density-weighted mean is that colour wherever there is
/// density, as the separate interpolation's is.
#[test]
fn one_colour_everywhere_renders_alike() {
    let data: Vec<f64> = [0.0, 1.5, 3.0, 0.25, 0.7, 0.0, 2.0, 0.1]
        .into_iter()
        .chain([0.2; 8])
        .chain([0.6; 8])
        .chain([0.9; 8])
        .collect();
    let volume = Tensor::from_vec(data, (4, 2, 2, 2), &Device::Cpu).unwrap();
    let rays = Rays::new(
        vec![[-3.0, 0.1, -0.2], [0.3, -3.0, 0.4], [0.0, 0.0, 3.0]],
        vec![[1.0, 0.05, 0.1], [-0.1, 1.0, 0.0], [0.02, -0.03, -1.0]],
    )
    .unwrap();
    let cfg = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 40 })
        .with_background(BACKGROUND)
        .with_depth(true);
    let run = |interpolation| {
        let out = render(
            &volume,
            &rays,
            &cfg.with_colour_interpolation(interpolation),
        )
        .unwrap();
        out.rgb.flatten_all().unwrap().to_vec1::<f64>().unwrap()
    };
    let separate = run(ColourInterpolation::Separate);
    let weighted = run(ColourInterpolation::DensityWeighted);
    for (a, b) in separate.iter().zip(&weighted) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
}

/// A density times colour that overflows is refused by name, not rendered as infinity.
#[test]
fn an_overflowing_premultiplied_colour_is_refused() {
    let volume = two_voxels(1e300, 0.0);
    let cfg = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 4 })
        .with_colour_interpolation(ColourInterpolation::DensityWeighted);
    let data = vec![1e300, 0.0, 1e10, 0.0, 0.0, 0.0, 0.0, 0.0];
    let huge = Tensor::from_vec(data, (4, 1, 1, 2), &Device::Cpu).unwrap();
    let err = render(&huge, &ray(), &cfg).unwrap_err().to_string();
    assert!(err.contains("density x colour overflows"), "{err}");
    assert!(render(&volume, &ray(), &cfg).is_ok());
}
