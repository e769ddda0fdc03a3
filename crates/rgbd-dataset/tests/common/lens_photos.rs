//! Photos as a lens with distortion takes them, made from pinhole renderings, and bilinear
//! samples to compare undistorted photos with the pinhole truth.

use rgbd_dataset::lens::Lens;

/// Bilinear sample of premultiplied RGBA at continuous pixel coordinates (edges clamped).
pub fn sample(photo: &image::RgbaImage, u: f64, v: f64) -> [f64; 4] {
    let (w, h) = (photo.width() as i64, photo.height() as i64);
    let (x, y) = (u - 0.5, v - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (tx, ty) = (x - x0, y - y0);
    let mut sum = [0.0; 4];
    for (di, dj, weight) in [
        (0, 0, (1.0 - tx) * (1.0 - ty)),
        (1, 0, tx * (1.0 - ty)),
        (0, 1, (1.0 - tx) * ty),
        (1, 1, tx * ty),
    ] {
        let i = (x0 as i64 + di).clamp(0, w - 1) as u32;
        let j = (y0 as i64 + dj).clamp(0, h - 1) as u32;
        let p = photo.get_pixel(i, j);
        let alpha = f64::from(p[3]) / 255.0;
        for c in 0..3 {
            sum[c] += weight * f64::from(p[c]) * alpha;
        }
        sum[3] += weight * alpha * 255.0;
    }
    sum
}

/// The photo `lens` takes with intrinsics `k` (`fx, fy, cx, cy`) of what `pinhole` shows with
/// the same intrinsics: each pixel shows what the pinhole's ray through its ideal point sees.
pub fn through_lens(pinhole: &image::RgbaImage, k: [f64; 4], lens: Lens) -> image::RgbaImage {
    image::RgbaImage::from_fn(pinhole.width(), pinhole.height(), |i, j| {
        let xd = (f64::from(i) + 0.5 - k[2]) / k[0];
        let yd = (f64::from(j) + 0.5 - k[3]) / k[1];
        let (x, y) = lens.undistort(xd, yd).unwrap();
        let p = sample(pinhole, k[0] * x + k[2], k[1] * y + k[3]);
        let alpha = p[3] / 255.0;
        let straight = |c: f64| if alpha > 0.0 { c / alpha } else { 0.0 };
        image::Rgba([
            straight(p[0]).round() as u8,
            straight(p[1]).round() as u8,
            straight(p[2]).round() as u8,
            p[3].round() as u8,
        ])
    })
}
