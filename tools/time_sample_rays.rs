//! `cargo run --release --example time_sample_rays -- [RAYS] [REPS]`: times drawing one training
//! batch alone (the `sample_rays` step, device timestamps of its dispatches) on the default Vulkan
//! device, next to the CPU twin, over `bench plenoxels`' views (40 views of 128²; random pixels
//! and cameras, which the draw's cost does not depend on). RAYS defaults to 4096 (the benches'
//! batch), REPS to 60 draws with seeds 1, 2, …; for the keys drawn on the device and on the host
//! (`gpu::KeyDraw`), prints min / median ms per draw (device, and the host's recording) and
//! whether every draw's keys equal the twin's. A measurement tool, not a test: figures go to docs/results.md.

use alphasurf::abi::buffers::SampleCamera;
use alphasurf::abi::rays::{Focus, SampleSet};
use alphasurf::cpu::sample_rays::sample_rays;
use alphasurf::gpu::{Gpu, KeyDraw, TrainViewBuffers};
use anyhow::{ensure, Context, Result};
use std::time::Instant;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: usize| -> Result<usize> {
        args.get(i).map_or(Ok(default), |s| {
            s.parse().with_context(|| {
                format!("'{s}' is not a count; usage: time_sample_rays [RAYS] [REPS]")
            })
        })
    };
    let (n, reps) = (arg(0, 4096)?, arg(1, 60)?);
    ensure!(n > 0 && reps > 0, "RAYS and REPS must be at least 1");

    let (w, h, n_views) = (128u32, 128u32, 40usize);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let images: Vec<Vec<u8>> = (0..n_views)
        .map(|_| (0..4 * w * h).map(|_| next() as u8).collect())
        .collect();
    let cam = |v: usize| SampleCamera {
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 1.0, 0.0],
        z_axis: [0.0, 0.0, 1.0],
        origin: [v as f32 * 0.01, 0.0, 2.0],
        focal: [w as f32, h as f32],
        centre: [0.5 * w as f32, 0.5 * h as f32],
    };
    let set = SampleSet {
        width: w,
        height: h,
        images: images.iter().map(|i| i.as_slice()).collect(),
        cams: (0..n_views).map(cam).collect(),
        focus: Focus::none(),
        ndc: None,
    };

    let gpu = Gpu::new(&Default::default())?;
    println!(
        "{n} rays over {n_views} views of {w}×{h}, {reps} draws on {}:",
        gpu.info().name
    );
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[0], v[v.len() / 2])
    };
    let mut twin_ms = Vec::new();
    for key_draw in [KeyDraw::Device, KeyDraw::Host] {
        let mut slot = None;
        let views = TrainViewBuffers::ensure(&mut slot, &gpu, 1, &set, n)?;
        views.key_draw = key_draw;
        let (mut device_ms, mut record_ms, mut identical) = (Vec::new(), Vec::new(), 0);
        // Device ms of each dispatch of the draw, per draw.
        let mut dispatch_ms: Vec<Vec<f64>> = Vec::new();
        // Draw 0 is untimed (first-dispatch compilation on lavapipe).
        for seed in 0..=reps as u64 {
            let mut b = gpu.batch()?;
            let t = Instant::now();
            views.record_sample(&mut b, &set, seed, n)?;
            let record = t.elapsed().as_secs_f64() * 1e3;
            let times = b.submit()?;
            let t = Instant::now();
            let want = sample_rays(&set, seed, n)?;
            let twin = t.elapsed().as_secs_f64() * 1e3;
            if seed == 0 {
                continue;
            }
            device_ms.push(times.total_ns() / 1e6);
            record_ms.push(record);
            dispatch_ms.resize(times.dispatches.len(), Vec::new());
            for (d, (_, ns)) in dispatch_ms.iter_mut().zip(&times.dispatches) {
                d.push(ns / 1e6);
            }
            twin_ms.push(twin);
            identical += (views.download_batch(n)?.keys == want.keys) as usize;
        }
        let (d_min, d_med) = stats(&mut device_ms);
        let (r_min, r_med) = stats(&mut record_ms);
        println!("  keys drawn on the {key_draw:?}:");
        println!("    device ms per draw: min {d_min:.3}, median {d_med:.3}");
        for (i, d) in dispatch_ms.iter_mut().enumerate() {
            let (min, med) = stats(d);
            println!("      dispatch {i}: min {min:.3}, median {med:.3}");
        }
        println!("    host ms recording the draw: min {r_min:.3}, median {r_med:.3}");
        println!("    draws whose keys equal the twin's: {identical} of {reps}");
    }
    let (t_min, t_med) = stats(&mut twin_ms);
    println!("  CPU twin ms per draw (the whole draw): min {t_min:.3}, median {t_med:.3}");
    Ok(())
}
