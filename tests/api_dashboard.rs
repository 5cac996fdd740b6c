//! What the dashboard reads beside the runs themselves (issue 13): a dataset's jobs with their
//! headline figures, a dataset's details (scale, bit depth, moves in mm and px), and the
//! speckle-quality figures of a snapshot.

use crate::common::daemon;

use daemon::{
    client, get, post, small_config, small_request, wait_terminal, TestServer, SCALE_PX_PER_MM,
};
use serde_json::{json, Value};

async fn post_json(server: &TestServer, path: &str, body: &Value) -> Value {
    post(&server.url(path), body).await.json().await.unwrap()
}

async fn get_json(server: &TestServer, path: &str) -> (u16, Value) {
    let r = get(&server.url(path)).await;
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dataset_lists_its_comparisons_and_details() {
    let dir = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(dir.path())).await;
    let run = post_json(&server, "/experiments", &small_request(2)).await;
    let run =
        wait_terminal(&server.url(&format!("/experiments/{}", run["id"].as_str().unwrap()))).await;
    assert_eq!(run["status"], "succeeded", "{run}");
    let ds = run["dataset_id"]
        .as_str()
        .expect("the experiment made a dataset");

    let (status, d) = get_json(&server, &format!("/datasets/{ds}/details")).await;
    assert_eq!(status, 200, "{d}");
    assert_eq!(d["scale_px_per_mm"], SCALE_PX_PER_MM);
    assert_eq!(d["bit_depth"], 16, "{d}");
    let runs = d["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2, "{d}");
    // small_request moves 0.5 mm and 1 mm along x: 6.5 and 13 px at 13 px/mm.
    for (r, mm) in runs.iter().zip([0.5, 1.0]) {
        assert_eq!(r["dx_mm"], mm, "{r}");
        assert!(
            (r["dx_px"].as_f64().unwrap() - mm * SCALE_PX_PER_MM).abs() < 1e-9,
            "{r}"
        );
        assert_eq!(r["dy_px"], 0.0);
        assert_eq!(r["pattern"], "a", "{r}");
    }

    // No job yet; then one comparison, listed with its discrepancy.
    let (status, jobs) = get_json(&server, &format!("/datasets/{ds}/jobs")).await;
    assert_eq!((status, jobs.as_array().unwrap().len()), (200, 0), "{jobs}");
    let body = json!({"model": "baseline", "schemes": ["ff100"],
                      "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}});
    let job = post_json(&server, &format!("/datasets/{ds}/comparisons"), &body).await;
    let job = wait_terminal(&server.url(&format!("/jobs/{}", job["id"].as_str().unwrap()))).await;
    assert_eq!(job["status"], "succeeded", "{job}");
    let (_, jobs) = get_json(&server, &format!("/datasets/{ds}/jobs")).await;
    let jobs = jobs.as_array().unwrap();
    assert_eq!(jobs.len(), 1, "{jobs:?}");
    assert_eq!(jobs[0]["id"], job["id"]);
    assert_eq!(jobs[0]["kind"], "comparison");
    assert_eq!(jobs[0]["status"], "succeeded");
    assert_eq!(jobs[0]["model"], "baseline");
    let (_, cmp) = get_json(
        &server,
        &format!(
            "/jobs/{}/files/results/comparison.json",
            job["id"].as_str().unwrap()
        ),
    )
    .await;
    assert_eq!(jobs[0]["discrepancy_px"], cmp["discrepancy_px"]);
    assert!(jobs[0]["discrepancy_px"].as_f64().unwrap() >= 0.0);

    let (status, _) = get_json(&server, "/datasets/ds-20260101t000000-nonexx/jobs").await;
    assert_eq!(status, 404);
    let (status, _) = get_json(&server, "/datasets/nope/details").await;
    assert_eq!(status, 404);
    server.stop().await;
}

/// The focus of the whole frame region by region (4x3) in a snapshot's quality figures `q`: the
/// mock bench's target is flat and in focus, so every region is about as sharp as the sharpest
/// (the print's density varies from region to region by a few %).
fn check_the_focus_map(q: &Value) {
    let focus = &q["focus"];
    assert_eq!(
        (focus["columns"].as_u64(), focus["rows"].as_u64()),
        (Some(4), Some(3)),
        "{q}"
    );
    let energy: Vec<f64> = focus["energy_dn2_per_px2"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect();
    assert_eq!(energy.len(), 12);
    let max = energy.iter().copied().fold(0.0, f64::max);
    assert!(energy.iter().all(|&e| e > 0.5 * max), "{energy:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_snapshot_carries_its_speckle_quality_only_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(dir.path())).await;
    let plain = client()
        .post(server.url("/camera/snapshot"))
        .send()
        .await
        .unwrap();
    assert_eq!(plain.status(), 200);
    assert!(plain.headers().get("x-speckle-quality").is_none());

    let r = client()
        .post(server.url("/camera/snapshot?quality=true&subset_px=31"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "image/tiff");
    let q: Value =
        serde_json::from_str(r.headers()["x-speckle-quality"].to_str().unwrap()).unwrap();
    assert_eq!(q["subset_px"], 31);
    // 400x320 px tiled by 31 px subsets (a one-pixel border kept for the gradients).
    assert_eq!(q["subsets"], (398 / 31) * (318 / 31), "{q}");
    assert!(q["mean_gradient_dn_per_px"].as_f64().unwrap() > 0.0, "{q}");
    // The mock bench's speckles are a few px wide: neither sub-pixel nor the whole frame.
    let size = q["speckle_size_px"].as_f64().expect("a speckle size");
    assert!((1.5..40.0).contains(&size), "{q}");
    let (sx, std_u) = (
        q["sssig_x_median_dn2"].as_f64().unwrap(),
        q["std_u_px_per_noise_dn"].as_f64().unwrap(),
    );
    assert!(
        (std_u - (2.0 / sx).sqrt()).abs() < 1e-12 * std_u.max(1.0),
        "{q}"
    );
    assert!(q["sssig_x_min_dn2"].as_f64().unwrap() <= sx);
    check_the_focus_map(&q);
    // The frame's own noise estimate against the temporal noise of two snapshots of the same
    // scene (an independent measurement: σ of their difference / √2).
    let noise_dn = q["noise_dn"].as_f64().unwrap();
    assert!(
        (q["std_u_px"].as_f64().unwrap() - std_u * noise_dn).abs() < 1e-12,
        "{q}"
    );
    let frame = |bytes: &[u8]| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.tif");
        std::fs::write(&path, bytes).unwrap();
        ffdic::image::read_tiff(&path).unwrap().0
    };
    let a = frame(&r.bytes().await.unwrap());
    let b = client()
        .post(server.url("/camera/snapshot"))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap();
    let b = frame(&b);
    let d: Vec<f64> = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(x, y)| (*x - *y) as f64)
        .collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    let temporal_dn =
        (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (d.len() - 1) as f64 / 2.0).sqrt();
    println!("noise: the header's {noise_dn:.2} DN, two later snapshots' {temporal_dn:.2} DN");
    // Two estimates of one noise from ≈ 128,000 pixel pairs each agree to a few per cent.
    assert!(
        (noise_dn / temporal_dn - 1.0).abs() < 0.1,
        "{noise_dn} vs {temporal_dn}"
    );

    let too_big = client()
        .post(server.url("/camera/snapshot?quality=true&subset_px=999"))
        .send()
        .await
        .unwrap();
    assert_eq!(too_big.status(), 422);
    server.stop().await;
}
