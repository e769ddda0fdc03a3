//! The browser check of `volgen view` (gated: `VIEW_BROWSER_CHECK=1`, run by
//! `tools/view/browser_check.sh` and by `.ci/run` where Chromium is installed): headless
//! Chromium with software WebGL (SwiftShader) loads the page, orbits, draws a new scene, varies
//! from scale 2 and downloads its VDB and camera. Each screenshot must show something, differ
//! from the one before when the view changed, and match volrender's rendering of the same
//! volume from the same camera (the page's texture, post-activated as the model renders it) and
//! `volgen render` of the downloaded `.safetensors` from the downloaded camera (PSNR).
//!
//! By default it trains a `micro` run; `VIEW_BROWSER_RUN=RUN VIEW_BROWSER_DATASET=DIR` checks an
//! existing run instead (the numbers in docs/cli.md are the demo's `tiny` run), and
//! `VIEW_BROWSER_SHOTS=DIR` keeps the screenshots (the README's picture of the page).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::Mat4;
use image::RgbImage;
use radiance_volume::{Aabb, RadianceVolume};
use serde_json::Value;
use volrender::{render_image, Camera, DensityInterpolation, RenderConfig, Sampler};

mod chrome;
#[path = "../common/mod.rs"]
mod common;

use chrome::Chrome;
use common::view::{micro_run, ViewServer};
use common::{ok, path, volgen};

/// Least agreement between a screenshot and volrender's rendering of the same texture (dB).
const MIN_PSNR_SAME_VOLUME: f64 = 40.0;
/// Least agreement between a screenshot and `volgen render` of the downloaded file (dB): that
/// file is the physical volume on a finer grid, not the grid the page draws.
const MIN_PSNR_CLI: f64 = 30.0;
/// Most agreement between screenshots that must differ (dB). The page draws the same state
/// identically (infinite PSNR); `micro`'s barely trained scenes change little from seed to seed
/// (36 dB between two seeds, 2026-12-06; a `tiny` run's 23 dB).
const MAX_PSNR_CHANGED: f64 = 45.0;

const WAIT: Duration = Duration::from_secs(120);

#[test]
fn the_page_draws_the_model_as_volgen_renders_it() {
    if std::env::var("VIEW_BROWSER_CHECK").as_deref() != Ok("1") {
        eprintln!(
            "skipped: set VIEW_BROWSER_CHECK=1 (needs chromium) or run tools/view/browser_check.sh"
        );
        return;
    }
    let (data, run) = match std::env::var_os("VIEW_BROWSER_RUN") {
        Some(run) => (
            PathBuf::from(std::env::var_os("VIEW_BROWSER_DATASET").expect("VIEW_BROWSER_DATASET")),
            PathBuf::from(run),
        ),
        None => micro_run("view_browser").clone(),
    };
    let shots = std::env::var_os("VIEW_BROWSER_SHOTS").map(PathBuf::from);
    let tmp = tempfile::tempdir().unwrap();
    let server = ViewServer::start(&[path(&run), "--dataset", path(&data)]);
    let mut chrome = Chrome::start(&tmp.path().join("profile"), 1200, 860);
    let downloads = tmp.path().join("downloads");
    std::fs::create_dir_all(&downloads).unwrap();
    chrome.download_into(&downloads);
    let mut check = Check {
        server: &server,
        chrome: &mut chrome,
        tmp: tmp.path(),
        shots,
        step: 0,
    };

    // Load: the first scene, seed 0, from the showcase camera.
    check
        .chrome
        .page
        .navigate(&format!("http://{}/", server.address));
    check.wait_frames(0);
    let loaded = check.shot("load");
    check.matches_volrender(&loaded);
    assert_eq!(check.scene()["seed"], "0");

    // Orbit: drag across the canvas; the camera turns, the picture changes.
    let centre = check.chrome.page.centre("#scene");
    let frames = check.frames();
    check.chrome.page.drag(centre, (70.0, 25.0), 7);
    check.wait_frames(frames);
    let orbited = check.shot("orbit");
    changed(&loaded, &orbited, "orbit");
    check.matches_volrender(&orbited);
    // Zoom: a turn of the wheel moves the camera out.
    let frames = check.frames();
    let before = check.camera_distance();
    check.chrome.page.wheel(centre, 240.0);
    check.wait_frames(frames);
    assert!(
        check.camera_distance() > before * 1.2,
        "the wheel zooms out"
    );
    let zoomed = check.shot("zoom");
    check.matches_volrender(&zoomed);

    // New scene: a new seed, shown in the seed box.
    let id = check.scene()["id"].clone();
    check.chrome.page.click("#new-scene");
    check.settle_scene(&id);
    let seed = check.scene()["seed"].as_str().unwrap().to_string();
    assert_eq!(
        check
            .chrome
            .page
            .eval("document.getElementById('seed').value"),
        seed
    );
    let fresh = check.shot("new-scene");
    changed(&zoomed, &fresh, "new scene");
    check.matches_volrender(&fresh);

    // Vary from scale 2: V*'s layout, this seed's finer noise.
    let id = check.scene()["id"].clone();
    check.chrome.page.eval(
        "(() => { const v = document.getElementById('vary'); v.value = '2'; \
         v.dispatchEvent(new Event('change')); })()",
    );
    check.settle_scene(&id);
    assert_eq!(check.scene()["vary"], 2);
    let varied = check.shot("vary-2");
    changed(&fresh, &varied, "vary from scale 2");
    check.matches_volrender(&varied);

    // Download its VDB: the file volgen sample writes for this seed and scale.
    let name = check.scene()["name"].as_str().unwrap().to_string();
    check.chrome.page.click("#download-vdb");
    let vdb = wait_for_file(&downloads.join(format!("{name}.vdb")));
    let sampled = tmp.path().join("sampled");
    ok(&volgen(&[
        "sample",
        path(&run),
        "--count",
        "1",
        "--seed",
        &seed,
        "--vary-from",
        "2",
        "--vdb",
        "--out",
        path(&sampled),
    ]));
    assert!(
        vdb == std::fs::read(sampled.join("scene_0.vdb")).unwrap(),
        "the downloaded VDB differs from volgen sample's"
    );
    // And the camera, for volgen render: the same picture as the page, from the file.
    check.chrome.page.click("#download-camera");
    wait_for_file(&downloads.join("view.json"));
    check.matches_volgen_render(&varied, &downloads.join("view.json"));

    // A training view (the strip shows the dataset's): the scene from its camera, the view
    // beside it.
    let strip = check
        .chrome
        .page
        .eval("document.querySelectorAll('#views button').length");
    assert!(strip.as_u64() > Some(1), "the strip has {strip} views");
    let frames = check.frames();
    check.chrome.page.click("#views button:nth-child(2)");
    check.wait_frames(frames);
    assert_eq!(
        check
            .chrome
            .page
            .eval("document.getElementById('training').hidden"),
        Value::Bool(false)
    );
    let from_view = check.shot("training-view");
    changed(&varied, &from_view, "training view");
    check.matches_volrender(&from_view);

    // Frame time of the software renderer (SwiftShader on this machine's CPU).
    let ms = check
        .chrome
        .page
        .eval("volgen.benchmark(20)")
        .as_f64()
        .unwrap();
    let samples = check.scene()["samples"].clone();
    println!("frame time, SwiftShader, 320x320, {samples} samples per ray: {ms:.1} ms");
    if let Some(dir) = &check.shots {
        let page = check.chrome.page.screenshot(None);
        std::fs::write(dir.join("page.png"), page).unwrap();
    }
}

/// The browser session, with where screenshots go.
struct Check<'a> {
    server: &'a ViewServer,
    chrome: &'a mut Chrome,
    tmp: &'a Path,
    shots: Option<PathBuf>,
    step: usize,
}

impl Check<'_> {
    /// The scene the page shows.
    fn scene(&mut self) -> Value {
        self.chrome.page.eval("volgen.scene()")
    }

    fn frames(&mut self) -> u64 {
        self.chrome.page.eval("volgen.frames()").as_u64().unwrap()
    }

    fn camera_distance(&mut self) -> f64 {
        let c2w = self.chrome.page.eval("volgen.camera().c2w");
        let p: Vec<f64> = (12..15).map(|i| c2w[i].as_f64().unwrap()).collect();
        let b = &self.scene()["box"];
        let centre: Vec<f64> = (0..3)
            .map(|i| (b[i].as_f64().unwrap() + b[i + 3].as_f64().unwrap()) / 2.0)
            .collect();
        (0..3)
            .map(|i| (p[i] - centre[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Waits until the page has drawn more than `frames` frames and waits for nothing.
    fn wait_frames(&mut self, frames: u64) {
        self.wait_until(&format!("volgen.frames() > {frames}"));
    }

    /// Waits until the page shows a scene other than `id`, drawn.
    fn settle_scene(&mut self, id: &Value) {
        self.wait_until(&format!("volgen.scene().id !== {id}"));
    }

    /// Waits until `condition` holds and the page waits for nothing, and for its last frame
    /// to reach the screen (the compositor shows it on the next animation frame). Until the
    /// page's script has run (just after navigating), `volgen` is not there yet.
    fn wait_until(&mut self, condition: &str) {
        self.chrome.page.wait_until(
            &format!("window.volgen !== undefined && volgen.idle() && {condition}"),
            WAIT,
        );
        self.chrome.page.eval(
            "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))",
        );
    }

    /// A screenshot of the canvas, checked not blank; kept when asked.
    fn shot(&mut self, what: &str) -> RgbImage {
        let png = self.chrome.page.screenshot(Some("#scene"));
        self.step += 1;
        if let Some(dir) = &self.shots {
            std::fs::create_dir_all(dir).unwrap();
            std::fs::write(dir.join(format!("{}-{what}.png", self.step)), &png).unwrap();
        }
        let image = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(image.dimensions(), (320, 320), "{what}");
        not_blank(&image, what);
        image
    }

    /// The page's texture rendered by volrender from the page's camera, as the model renders
    /// it (its samples, density rule and background; exact, no early termination).
    fn volrender_reference(&mut self) -> RgbImage {
        let scene = self.scene();
        let bytes = self.server.ok(scene["volume"].as_str().unwrap());
        let dims: Vec<usize> = (0..3)
            .map(|i| scene["dims"][i].as_u64().unwrap() as usize)
            .collect();
        let (w, h, d) = (dims[0], dims[1], dims[2]);
        let values: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let tensor = candle_core::Tensor::from_vec(values, (d, h, w, 4), &candle_core::Device::Cpu)
            .unwrap()
            .permute((3, 0, 1, 2))
            .unwrap()
            .contiguous()
            .unwrap();
        let b: Vec<f32> = (0..6)
            .map(|i| scene["box"][i].as_f64().unwrap() as f32)
            .collect();
        let aabb = Aabb::try_new(
            glam::Vec3::new(b[0], b[1], b[2]),
            glam::Vec3::new(b[3], b[4], b[5]),
        );
        let volume = RadianceVolume::new(tensor, aabb.unwrap()).unwrap();
        let density = match scene["density"]["rule"].as_str().unwrap() {
            "post-activated" => DensityInterpolation::PostActivated {
                scale: scene["density"]["scale"].as_f64().unwrap() as f32,
                shift: scene["density"]["shift"].as_f64().unwrap() as f32,
            },
            _ => DensityInterpolation::Physical,
        };
        let background: Vec<f32> = (0..3)
            .map(|i| scene["background"][i].as_f64().unwrap() as f32)
            .collect();
        let cfg = RenderConfig::default()
            .with_sampler(Sampler::Uniform {
                samples: scene["samples"].as_u64().unwrap() as usize,
            })
            .with_background([background[0], background[1], background[2]])
            .with_density(density);
        let image = render_image(&volume, &self.page_camera(), &cfg).unwrap();
        RgbImage::from_fn(image.width as u32, image.height as u32, |x, y| {
            let c = image.rgb[y as usize * image.width + x as usize];
            image::Rgb(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
        })
    }

    fn page_camera(&mut self) -> Camera {
        let cam = self.chrome.page.eval("volgen.camera()");
        let c2w: Vec<f32> = (0..16)
            .map(|i| cam["c2w"][i].as_f64().unwrap() as f32)
            .collect();
        let number = |k: &str| cam[k].as_f64().unwrap() as f32;
        Camera::from_intrinsics(
            Mat4::from_cols_slice(&c2w),
            cam["width"].as_u64().unwrap() as usize,
            cam["height"].as_u64().unwrap() as usize,
            [number("fx"), number("fy"), number("cx"), number("cy")],
        )
        .unwrap()
    }

    /// The screenshot agrees with volrender's rendering of the page's own texture.
    fn matches_volrender(&mut self, shot: &RgbImage) {
        let reference = self.volrender_reference();
        let db = psnr(shot, &reference);
        println!(
            "step {}: page vs volrender of the same volume and camera: {db:.2} dB",
            self.step
        );
        if let Some(dir) = &self.shots {
            reference
                .save(dir.join(format!("{}-volrender.png", self.step)))
                .unwrap();
        }
        assert!(db >= MIN_PSNR_SAME_VOLUME, "{db:.2} dB");
    }

    /// The screenshot agrees with `volgen render` of the scene's `.safetensors` download from
    /// the camera the page downloaded.
    fn matches_volgen_render(&mut self, shot: &RgbImage, camera: &Path) {
        let scene = self.scene();
        let file = self.tmp.join("scene.safetensors");
        std::fs::write(
            &file,
            self.server
                .ok(scene["downloads"]["safetensors"].as_str().unwrap()),
        )
        .unwrap();
        let background = (0..3)
            .map(|i| scene["background"][i].to_string())
            .collect::<Vec<_>>()
            .join(",");
        let out = self.tmp.join("rendered");
        let samples = scene["samples"].to_string();
        ok(&volgen(&[
            "render",
            path(&file),
            "--cameras",
            path(camera),
            "--width",
            "320",
            "--height",
            "320",
            "--samples",
            &samples,
            "--background",
            &background,
            "--out",
            path(&out),
        ]));
        let rendered = image::open(out.join("view.png")).unwrap().to_rgb8();
        let db = psnr(shot, &rendered);
        println!(
            "step {}: page vs volgen render of {}.safetensors (--samples {samples} --background \
             {background}): {db:.2} dB",
            self.step,
            scene["name"].as_str().unwrap()
        );
        assert!(db >= MIN_PSNR_CLI, "{db:.2} dB");
    }
}

/// PSNR of two 8-bit images (dB; infinite when equal).
fn psnr(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
        .sum();
    let mse = sum / a.as_raw().len() as f64;
    10.0 * (255.0 * 255.0 / mse).log10()
}

/// At least 2% of the pixels differ from the most common colour (the background) by more than
/// 8 levels: the screenshot shows something.
fn not_blank(image: &RgbImage, what: &str) {
    let mut counts = std::collections::HashMap::new();
    for p in image.pixels() {
        *counts.entry(p.0).or_insert(0usize) += 1;
    }
    let (common, _) = counts.iter().max_by_key(|(_, n)| **n).unwrap();
    let differing = image
        .pixels()
        .filter(|p| (0..3).any(|c| (i32::from(p.0[c]) - i32::from(common[c])).abs() > 8))
        .count();
    let share = differing as f64 / (image.width() * image.height()) as f64;
    assert!(
        share >= 0.02,
        "{what}: blank ({:.1}% of pixels differ from {common:?})",
        100.0 * share
    );
}

/// The screenshots differ (a view that changed).
fn changed(before: &RgbImage, after: &RgbImage, what: &str) {
    let db = psnr(before, after);
    assert!(
        db < MAX_PSNR_CHANGED,
        "{what}: the picture did not change ({db:.1} dB)"
    );
}

/// The file's bytes once the download has finished.
fn wait_for_file(file: &Path) -> Vec<u8> {
    let started = Instant::now();
    loop {
        if file.is_file() {
            return std::fs::read(file).unwrap();
        }
        assert!(started.elapsed() < WAIT, "no download {}", file.display());
        std::thread::sleep(Duration::from_millis(100));
    }
}
