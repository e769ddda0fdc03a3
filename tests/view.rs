//! `volgen view` without a browser: it serves its page and the scenes it drew and nothing else
//! (path traversal and absolute paths are 404), refuses bad parameters with a one-line 400,
//! serves the very files `volgen sample` and `volgen animate` write, stays within bounded
//! memory and time under 100 concurrent requests, and refuses a broken run before serving.

use std::time::{Duration, Instant};

mod common;
use common::view::{get, micro_run, same_file, same_safetensors, ViewServer};
use common::{failure, ok, path, volgen};

/// The micro run of this test binary, served with its dataset.
fn serve_micro() -> ViewServer {
    let (data, run) = micro_run("view");
    ViewServer::start(&[path(run), "--dataset", path(data)])
}

#[test]
fn serves_its_page_and_nothing_else() {
    let server = serve_micro();
    let page = server.get("/");
    assert_eq!(page.status, 200);
    assert!(page
        .header("content-type")
        .unwrap()
        .starts_with("text/html"));
    assert!(
        page.text().contains("<canvas id=\"scene\""),
        "{}",
        page.text()
    );
    // The page may load nothing from elsewhere.
    let policy = page.header("content-security-policy").unwrap();
    assert!(policy.contains("default-src 'none'") && policy.contains("script-src 'self'"));
    assert!(String::from_utf8(server.ok("/view.js"))
        .unwrap()
        .contains("texelFetch"));
    let info = server.json("/api/info");
    assert_eq!(info["kind"], "model");
    assert_eq!(info["scales"], 2, "micro has two 3D scales");
    assert_eq!(info["views"].as_array().unwrap().len(), 6);
    assert_eq!(&server.ok("/views/0.png")[1..4], b"PNG");
    // A scene it drew, and its texture: 16 bytes per voxel.
    let scene = server.json("/api/scene?seed=1");
    let dims: Vec<u64> = scene["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_u64().unwrap())
        .collect();
    let texture = server.ok(scene["volume"].as_str().unwrap());
    assert_eq!(texture.len() as u64, dims.iter().product::<u64>() * 16);

    let (_, run) = micro_run("view");
    let checkpoint = run.canonicalize().unwrap().join("checkpoint.safetensors");
    let absolute = checkpoint.to_str().unwrap().to_string();
    let id = scene["id"].as_u64().unwrap();
    for target in [
        "/../../etc/passwd",
        "/../../../../../../etc/passwd",
        "/..%2F..%2Fetc%2Fpasswd",
        "/%2e%2e/%2e%2e/etc/passwd",
        "/%2E%2E%2F%2E%2E%2Fetc%2Fpasswd",
        "/..%252F..%252Fetc%252Fpasswd",
        "//etc/passwd",
        "/etc/passwd",
        "/view.js/../../etc/passwd",
        "/scenes/../../etc/passwd",
        &format!("/scenes/{id}/..%2F..%2F..%2Fetc%2Fpasswd"),
        &format!("/scenes/{id}/../../../etc/passwd"),
        "/scenes/..%2F..%2Fetc/passwd",
        "/scenes/%FF/volume",
        "/views/..%2F..%2Fetc%2Fpasswd",
        "/views/0.png/../../../../etc/passwd",
        "/views/-1.png",
        "/views/6.png",
        "/C:/Windows/win.ini",
        "/checkpoint.safetensors",
        "/run/checkpoint.safetensors",
        // The run's own files by their absolute paths exist, and are not served either.
        &absolute,
        &format!("/{absolute}"),
        &format!("/views/{}", absolute.replace('/', "%2F")),
        // Scenes it never drew, and files no scene has.
        "/scenes/999999/volume",
        &format!("/scenes/{id}/scene_seed1.exe"),
        &format!("/scenes/{id}/scene_seed2.vdb"),
        &format!("/scenes/{id}/"),
        "/api/",
        "/api/scene/extra",
    ] {
        let response = server.get(target);
        assert_eq!(response.status, 404, "{target}: {}", response.text());
        let text = response.text();
        assert!(
            !text.contains("root:") && !text.contains("safetensors"),
            "{target}: {text}"
        );
    }
    // An absolute-form request target names a path on this server, no other file.
    let absolute_form = server.get(&format!("http://{}/../../etc/passwd", server.address));
    assert_eq!(absolute_form.status, 404, "{}", absolute_form.text());
}

#[test]
fn bad_parameters_get_a_one_line_400() {
    let server = serve_micro();
    for (query, starts) in [
        ("seed=abc", "seed: expected a whole number"),
        ("seed=-3", "seed:"),
        ("seed=18446744073709551616", "seed:"),
        ("vary=3", "vary: expected a 3D scale from 1 to 2"),
        ("vary=0", "vary:"),
        ("extent=0,1,1", "extent:"),
        ("extent=0", "extent:"),
        ("extent=5,1,1", "extent: the viewer draws scenes up to 4"),
        ("extent=2,1,1&vary=2", "vary:"),
        ("extent=2,1,1&outside=wrap", "outside:"),
        ("walk=-1", "walk:"),
        ("walk=121", "walk:"),
        ("file=0", "unknown parameter `file`"),
        ("seed=1&seed=2", "parameter `seed` is given twice"),
    ] {
        let response = server.get(&format!("/api/scene?{query}"));
        assert_eq!(response.status, 400, "{query}: {}", response.text());
        let text = response.text();
        assert!(text.starts_with(starts), "{query}: {text}");
        assert_eq!(text.trim_end().lines().count(), 1, "{query}: {text}");
    }
}

#[test]
fn scenes_download_as_the_files_the_cli_writes() {
    let server = serve_micro();
    let (_, run) = micro_run("view");
    let tmp = tempfile::tempdir().unwrap();
    let (sampled, animated) = (tmp.path().join("sampled"), tmp.path().join("animated"));
    ok(&volgen(&[
        "sample",
        path(run),
        "--count",
        "1",
        "--seed",
        "5",
        "--vary-from",
        "2",
        "--vdb",
        "--out",
        path(&sampled),
    ]));
    let scene = server.json("/api/scene?seed=5&vary=2");
    assert_eq!(scene["name"], "scene_seed5_vary2");
    for format in ["safetensors", "vdb"] {
        let response = server.get(scene["downloads"][format].as_str().unwrap());
        assert_eq!(response.status, 200, "{format}: {}", response.text());
        assert_eq!(
            response.header("content-disposition"),
            Some(format!("attachment; filename=\"scene_seed5_vary2.{format}\"").as_str())
        );
        let cli = std::fs::read(sampled.join(format!("scene_0.{format}"))).unwrap();
        assert!(
            same_file(format, &response.body, &cli),
            "{format}: the download differs from volgen sample's"
        );
    }
    // The mesh is `volgen mesh`'s of that volume (`sample --mesh glb` makes it so): the same
    // bytes, or, where micro's thin matter has no surface at the default level, the same
    // refusal (a 422 saying why).
    let glb = server.get(scene["downloads"]["glb"].as_str().unwrap());
    let meshed = tmp.path().join("scene_0.glb");
    let cli = volgen(&[
        "mesh",
        path(&sampled.join("scene_0.safetensors")),
        "--out",
        path(&meshed),
    ]);
    if cli.status.success() {
        assert_eq!(glb.status, 200, "{}", glb.text());
        assert!(glb.body == std::fs::read(&meshed).unwrap());
    } else {
        assert_eq!(glb.status, 422, "{}", glb.text());
        assert!(failure(&cli).contains("no surface"));
        assert!(glb.text().contains("no surface"), "{}", glb.text());
        assert_eq!(glb.text().trim_end().lines().count(), 1, "{}", glb.text());
    }
    // Frame 2 of the noise walk is frame 2 of volgen animate from the same seed.
    ok(&volgen(&[
        "animate",
        path(run),
        "--frames",
        "3",
        "--seed",
        "5",
        "--out",
        path(&animated),
    ]));
    let walked = server.json("/api/scene?seed=5&walk=2");
    let download = server.ok(walked["downloads"]["safetensors"].as_str().unwrap());
    let frame = std::fs::read(animated.join("frame_0002.safetensors")).unwrap();
    assert!(same_safetensors(&download, &frame));
    // Walk frame 0 is the seed's scene itself, not frame 2.
    let first = server.json("/api/scene?seed=5");
    assert_ne!(
        server.ok(first["volume"].as_str().unwrap()),
        server.ok(walked["volume"].as_str().unwrap())
    );
}

#[cfg(target_os = "linux")]
#[test]
fn a_load_loop_of_100_concurrent_requests_stays_bounded() {
    let server = serve_micro();
    // Warm: the first scene, so the peak below measures the burst, not start-up.
    server.json("/api/scene?seed=0");
    let before = server.peak_kib();
    let started = Instant::now();
    let address = server.address.clone();
    let handles: Vec<_> = (0..100)
        .map(|i| {
            let address = address.clone();
            std::thread::spawn(move || {
                // Mostly new scenes (each a generation), some downloads and pages.
                let target = match i % 10 {
                    0 => "/".to_string(),
                    1 => "/api/info".to_string(),
                    2 => "/scenes/1/scene_seed0.vdb".to_string(),
                    _ => format!("/api/scene?seed={}&walk={}", 1000 + i, i % 4),
                };
                (target.clone(), get(&address, &target))
            })
        })
        .collect();
    let mut counts = std::collections::BTreeMap::new();
    for handle in handles {
        let (target, response) = handle.join().unwrap();
        assert!(
            response.status == 200 || response.status == 503,
            "{target}: {} {}",
            response.status,
            response.text()
        );
        if response.status == 503 {
            assert!(response.text().starts_with("busy:"), "{}", response.text());
            assert_eq!(response.header("retry-after"), Some("1"));
        }
        *counts.entry(response.status).or_insert(0) += 1;
    }
    let seconds = started.elapsed().as_secs_f64();
    let grew_mib = (server.peak_kib() - before) as f64 / 1024.0;
    println!(
        "100 concurrent requests: {counts:?} in {seconds:.2} s, peak memory +{grew_mib:.1} MiB"
    );
    assert!(seconds < 60.0, "{seconds} s");
    // A micro scene is kilobytes: what grows is the threads' and the queue's working memory.
    assert!(
        grew_mib < 64.0,
        "peak resident memory grew by {grew_mib:.1} MiB"
    );
    // And it still answers.
    assert_eq!(server.get("/api/info").status, 200);
}

#[test]
fn serves_a_directory_of_volumes_and_one_volume() {
    let (_, run) = micro_run("view");
    let tmp = tempfile::tempdir().unwrap();
    let scenes = tmp.path().join("scenes");
    ok(&volgen(&[
        "sample",
        path(run),
        "--count",
        "2",
        "--out",
        path(&scenes),
    ]));
    let server = ViewServer::start(&[path(&scenes)]);
    let info = server.json("/api/info");
    assert_eq!(info["kind"], "files");
    assert_eq!(info["files"], serde_json::json!(["scene_0", "scene_1"]));
    let scene = server.json("/api/scene?file=1");
    assert_eq!(scene["density"]["rule"], "physical");
    let download = server.ok(scene["downloads"]["safetensors"].as_str().unwrap());
    assert!(download == std::fs::read(scenes.join("scene_1.safetensors")).unwrap());
    let refused = server.get("/api/scene?file=2");
    assert_eq!(refused.status, 400);
    assert!(refused
        .text()
        .starts_with("file: expected a scene from 0 to 1"));
    assert_eq!(server.get("/api/scene?seed=1").status, 400);
    drop(server);
    let one = ViewServer::start(&[path(&scenes.join("scene_0.safetensors"))]);
    assert_eq!(
        one.json("/api/info")["files"],
        serde_json::json!(["scene_0"])
    );
}

#[test]
fn a_volume_downloads_as_volgen_export_and_volgen_mesh_write_it() {
    // A ball of dense orange matter: a volume with a surface to mesh.
    let ball = radiance_volume::RadianceVolume::from_fn(
        radiance_volume::GridDims::cube(20),
        radiance_volume::Aabb::CUBE,
        4,
        |p, out| {
            out[0] = if p.length() < 0.6 { 40.0 } else { 0.0 };
            out[1..4].copy_from_slice(&[0.9, 0.5, 0.1]);
        },
    )
    .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("ball.safetensors");
    ball.save_safetensors(&file).unwrap();
    let (vdb, glb) = (tmp.path().join("ball.vdb"), tmp.path().join("ball.glb"));
    ok(&volgen(&["export", path(&file), "--vdb", path(&vdb)]));
    ok(&volgen(&["mesh", path(&file), "--out", path(&glb)]));
    let server = ViewServer::start(&[path(&file)]);
    let scene = server.json("/api/scene");
    assert_eq!(scene["name"], "ball");
    for (format, cli) in [("safetensors", &file), ("vdb", &vdb), ("glb", &glb)] {
        let response = server.get(scene["downloads"][format].as_str().unwrap());
        assert_eq!(response.status, 200, "{format}: {}", response.text());
        assert!(
            response.body == std::fs::read(cli).unwrap(),
            "{format}: the download differs from the CLI's file"
        );
    }
}

#[test]
fn a_run_that_cannot_be_loaded_is_refused_before_serving() {
    let (_, run) = micro_run("view");
    let tmp = tempfile::tempdir().unwrap();
    let broken = tmp.path().join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    // A checkpoint cut short, as a full disk leaves it.
    let bytes = std::fs::read(run.join("checkpoint.safetensors")).unwrap();
    std::fs::write(
        broken.join("checkpoint.safetensors"),
        &bytes[..bytes.len() / 2],
    )
    .unwrap();
    let started = Instant::now();
    let out = volgen(&["view", path(&broken), "--port", "0"]);
    let err = failure(&out);
    assert!(err.contains("checkpoint.safetensors"), "{err}");
    assert!(!String::from_utf8_lossy(&out.stdout).contains("http://"));
    assert!(started.elapsed() < Duration::from_secs(60));
    // Nothing there at all, and a volume that is not one.
    let missing = failure(&volgen(&[
        "view",
        path(&tmp.path().join("nothing")),
        "--port",
        "0",
    ]));
    assert!(
        missing.contains("nothing") && missing.contains("no such"),
        "{missing}"
    );
    let junk = tmp.path().join("junk.safetensors");
    std::fs::write(&junk, b"not a volume").unwrap();
    let err = failure(&volgen(&["view", path(&junk), "--port", "0"]));
    assert!(err.contains("junk.safetensors"), "{err}");
    // A dataset given explicitly must load.
    let err = failure(&volgen(&[
        "view",
        path(run),
        "--dataset",
        path(&tmp.path().join("no-dataset")),
        "--port",
        "0",
    ]));
    assert!(err.contains("no-dataset"), "{err}");
}

#[test]
fn says_so_when_it_listens_beyond_the_loopback() {
    let (_, run) = micro_run("view");
    let server = ViewServer::start(&[path(run), "--host", "0.0.0.0"]);
    // The warning comes before the URL, which start() waited for.
    std::thread::sleep(Duration::from_millis(200));
    let said = server.stderr();
    assert!(
        said.contains("warning") && said.contains("not the loopback"),
        "{said}"
    );
    let quiet = serve_micro();
    std::thread::sleep(Duration::from_millis(200));
    assert!(!quiet.stderr().contains("warning"), "{}", quiet.stderr());
}
