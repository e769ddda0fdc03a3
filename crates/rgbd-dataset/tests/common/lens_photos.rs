//! Bilinear samples (in f64, written apart from the library's) to compare undistorted photos
//! with the pinhole truth.

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
