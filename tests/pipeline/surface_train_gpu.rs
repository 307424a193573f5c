//! The Vulkan stage-2 backend against the CPU one (lavapipe, validation layers on): a few training
//! steps from the same grid on the same batches, with every regulariser (Lδ, TVα, Lα, Ln1/Ln2)
//! and a learned background.
//! The kernel-level parity (per-ray losses, gradients, touched flags, counters) is the
//! `surface_train` row of `check-kernels`, asserted in tests/kernels/parity.rs.

use alphasurf::abi::regularisers::{delta_tv_chunk, opacity_tv_chunk, OpacityChunk};
use alphasurf::check::rel_l2;
use alphasurf::check::surface_fwd::{test_rays, test_scene};
use alphasurf::check::surface_train::{scene_grid, test_background};
use alphasurf::gpu::test_gpu;
use alphasurf::grid::surface::SurfaceGrid;
use alphasurf::stage::StageBackend;
use alphasurf::surface::{
    CpuSurface, SurfaceBackend, SurfaceRegs, SurfaceStepParams, VulkanSurface,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Step parameters with every regulariser on; chunks that move with the step and wrap.
fn params(g: &SurfaceGrid, step: u32) -> SurfaceStepParams {
    let rows = g.delta.len() as u32;
    SurfaceStepParams {
        lr_delta: 1e-3,
        lr_opacity: 1e-2,
        lr_sh: 1e-2,
        beta: 0.95,
        eps: 1e-8,
        truncation: 3.5.into(),
        stop_thresh: 1e-4,
        lambda_h: 1e-2,
        lambda_c: 1e-2,
        lr_bg: 1e-2,
        regs: SurfaceRegs {
            // Whole-grid Lδ (dense δ update) and a 30 % chunk (δ flagged) in turn.
            delta_tv: Some(delta_tv_chunk(
                g.res,
                rows,
                if step.is_multiple_of(2) { 1.0 } else { 0.3 },
                1e-3,
                step as u64 * 4099,
            )),
            opacity_tv: Some(opacity_tv_chunk(g.res, 0.1, 1e-3, step as u64 * 997)),
            opacity_log: Some(OpacityChunk {
                rows,
                start: rows - 500 + step * 131,
                count: rows / 5,
                lambda: 1e-3,
            }),
            // A chunk of 60 % and one of 12 % in turn: each step's passes visit only the chunk's
            // window, over per-row arrays another chunk wrote before.
            normals: Some((
                rows / 2 + step * 777,
                if step.is_multiple_of(2) {
                    rows * 3 / 5
                } else {
                    rows / 8
                },
                1e-2,
                1e-3,
            )),
        },
    }
}

/// The parameter change of each group from `g0` to `g`.
fn updates(g0: &SurfaceGrid, g: &SurfaceGrid) -> [Vec<f32>; 3] {
    let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| x - y).collect();
    [
        diff(&g.delta, &g0.delta),
        diff(&g.opacity, &g0.opacity),
        diff(&g.sh, &g0.sh),
    ]
}

#[test]
fn vulkan_steps_match_cpu_steps() {
    let gpu = test_gpu();
    let scene = test_scene(11, 24);
    let g0 = scene_grid(&scene);
    let mut vk = VulkanSurface::new(gpu, g0.clone()).unwrap();
    let mut cpu = CpuSurface::new(g0.clone()).unwrap();
    vk.set_background(test_background()).unwrap();
    cpu.set_background(test_background()).unwrap();
    let mut rng = Pcg64::seed_from_u64(5);
    for step in 0..5u32 {
        let rays = test_rays(&scene, 100 + step as u64, 2000);
        let targets: Vec<f32> = (0..rays.len() / 2).map(|_| rng.random()).collect();
        let p = params(&g0, step);
        let sv = vk.step(&rays, &targets, &p).unwrap();
        let sc = cpu.step(&rays, &targets, &p).unwrap();
        assert!(sv.timing.device_ns > 0.0 && sc.timing.device_ns == 0.0);
        // The grids drift apart by rounding only (measured: ~1e-8 relative over 5 steps).
        eprintln!(
            "step {step}: mse {} / {}, entropy {} / {}, consistency {} / {}",
            sv.mse, sc.mse, sv.entropy, sc.entropy, sv.consistency, sc.consistency
        );
        for (what, v, c) in [
            ("mse", sv.mse, sc.mse),
            ("entropy", sv.entropy, sc.entropy),
            ("consistency", sv.consistency, sc.consistency),
            ("regulariser loss", sv.reg_loss, sc.reg_loss),
        ] {
            assert!(
                (v - c).abs() <= 1e-5 * c.abs() + 1e-8,
                "step {step} {what}: vulkan {v} cpu {c}"
            );
        }
        let (v, c) = (sv.counts, sc.counts);
        assert_eq!(v.hits, c.hits, "step {step} hits");
        // Skipped blocks' edge differs by backend (SURF_BLOCK_SHIFT_*: 4³ on Vulkan, 8³ on the
        // CPU): more, smaller ones on Vulkan.
        assert!(
            v.blocks_skipped > c.blocks_skipped && c.blocks_skipped > 0,
            "step {step} blocks skipped: vulkan {} cpu {}",
            v.blocks_skipped,
            c.blocks_skipped
        );
        for (what, v, c) in [
            ("cells", v.cells, c.cells),
            ("solves", v.solves, c.solves),
            ("culled", v.culled, c.culled),
            ("cut", v.cut, c.cut),
            ("guarded", v.guarded, c.guarded),
            ("atomic adds", v.atomic_adds, c.atomic_adds),
        ] {
            let (v, c) = (v as f64, c as f64);
            assert!(
                (v - c).abs() <= 1e-3 * c + 2.0,
                "step {step} {what}: {:?} vs {:?}",
                sv.counts,
                sc.counts
            );
        }
    }
    // The learned background: five RMSProp steps of about lr each, from (0.2, 0.6, 0.9), on
    // gradients summed in another order.
    let (bv, bc) = (vk.background().unwrap(), cpu.background().unwrap());
    eprintln!("background: vulkan {:?} cpu {:?}", bv.rgb, bc.rgb);
    for ch in 0..3 {
        assert!(
            (bv.rgb[ch] - bc.rgb[ch]).abs() <= 1e-5 && bc.rgb[ch] != test_background().rgb[ch],
            "background: vulkan {bv:?} cpu {bc:?}"
        );
    }
    let (gv, gc) = (vk.grid().unwrap(), cpu.grid().unwrap());
    assert_eq!(gv.links, gc.links);
    // RMSProp normalises every touched element's step to about lr, so an element whose gradient
    // sums to nearly zero could move either way on the two backends: compare the updates in
    // aggregate (measured ~1e-5 relative L2), and the parameters elementwise within 2.5 learning
    // rates (one such sign flip; measured: none, max |Δ| ≤ 2e-5).
    let (uv, uc) = (updates(&g0, &gv), updates(&g0, &gc));
    for (t, name) in ["δ", "σα", "SH"].iter().enumerate() {
        let e = rel_l2(&uv[t], &uc[t]);
        eprintln!("{name}: update rel L2 {e:.2e}");
        assert!(e <= 1e-3, "{name} update rel L2 {e:.2e}");
        let moved = uc[t].iter().filter(|&&x| x != 0.0).count();
        assert!(moved > 100, "{name}: only {moved} elements moved");
    }
    for (name, a, b, lr) in [
        ("δ", &gv.delta, &gc.delta, 1e-3f32),
        ("σα", &gv.opacity, &gc.opacity, 1e-2),
        ("SH", &gv.sh, &gc.sh, 1e-2),
    ] {
        let worst = a
            .iter()
            .zip(b.iter())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        eprintln!("{name}: max |Δ| {worst:.2e}");
        assert!(worst <= 2.5 * lr, "{name}: max |Δ| {worst}");
    }
    let (sv, sc) = (
        vk.optimizer_state().unwrap(),
        cpu.optimizer_state().unwrap(),
    );
    for t in 0..3 {
        let e = rel_l2(&sv[t], &sc[t]);
        assert!(e <= 1e-3, "RMS state {t}: rel L2 {e:.2e}");
    }
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

#[test]
fn vulkan_render_and_load_round_trip() {
    let gpu = test_gpu();
    let scene = test_scene(3, 24);
    let g0 = scene_grid(&scene);
    let rays = test_rays(&scene, 9, 1500);
    let mut vk = VulkanSurface::new(gpu, g0.clone()).unwrap();
    let mut cpu = CpuSurface::new(g0.clone()).unwrap();
    let (rv, cv) = vk.render(&rays, 3.5.into(), 1e-4).unwrap();
    let (rc, cc) = cpu.render(&rays, 3.5.into(), 1e-4).unwrap();
    assert_eq!(rv.len(), rc.len());
    let close = rv
        .iter()
        .zip(&rc)
        .filter(|(a, b)| (*a - *b).abs() <= 1e-4 + 1e-4 * b.abs())
        .count();
    assert!(
        close * 1000 >= rc.len() * 995,
        "{close} of {} channels agree",
        rc.len()
    );
    assert_eq!(cv.hits, cc.hits, "hits composited");
    // load() replaces the grid and the optimiser state.
    assert_eq!(vk.grid().unwrap(), g0);
    let n = g0.delta.len();
    let state = [vec![0.5f32; n], vec![0.25; n], vec![0.125; 27 * n]];
    let mut g1 = g0.clone();
    g1.opacity.iter_mut().for_each(|o| *o += 1.0);
    vk.set_background(test_background()).unwrap();
    vk.load(g1.clone(), Some(state.clone())).unwrap();
    assert_eq!(
        vk.background().unwrap(),
        test_background(),
        "load keeps the background"
    );
    assert_eq!(vk.grid().unwrap(), g1);
    assert_eq!(vk.optimizer_state().unwrap(), state);
    assert!(vk.load(g1, Some([vec![], vec![], vec![]])).is_err());
    // Inputs that must be refused, not crash the device.
    let p = SurfaceStepParams {
        truncation: 9.0.into(),
        ..params(&g0, 0)
    };
    assert!(vk.step(&rays[..60], &[0.5; 30], &p).is_err());
    assert!(vk.step(&rays[..60], &[0.5; 29], &params(&g0, 0)).is_err());
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

/// A link past the vertex rows is an error when the CPU backend is made, not a panic; its passes,
/// which skip the range check (the links never change), give the same result each time.
#[test]
fn cpu_backend_checks_links_when_made() {
    let scene = test_scene(11, 24);
    let g0 = scene_grid(&scene);
    let rays = test_rays(&scene, 7, 200);
    let mut bad = g0.clone();
    let s = bad.links.iter().position(|&l| l >= 0).unwrap();
    bad.links[s] = bad.delta.len() as i32;
    let err = CpuSurface::new(bad).err().expect("a bad link is an error");
    assert!(format!("{err:#}").contains("link"), "{err:#}");
    let mut cpu = CpuSurface::new(g0).unwrap();
    let first = cpu.render(&rays, 5.0.into(), 1e-4).unwrap();
    let again = cpu.render(&rays, 5.0.into(), 1e-4).unwrap();
    assert!(
        first.1.cut + first.1.cells > 0,
        "the rays walk cells: {:?}",
        first.1
    );
    assert_eq!(first, again);
}

/// Both backends of each stage count a checkpoint's copy (`state_bytes`, which decides whether
/// it is written in the background) as the bytes of the arrays a checkpoint holds.
#[test]
fn state_bytes_are_the_checkpoint_arrays() {
    use alphasurf::plenoxel::{CpuPlenoxels, VulkanPlenoxels};
    use alphasurf::stage::StageBackend;
    let gpu = test_gpu();
    let g0 = scene_grid(&test_scene(11, 24));
    let (vk, cpu) = (
        VulkanSurface::new(gpu, g0.clone()).unwrap(),
        CpuSurface::new(g0.clone()).unwrap(),
    );
    let [sd, so, ss] = cpu.optimizer_state().unwrap();
    let arrays = [&g0.delta, &g0.opacity, &g0.sh, &sd, &so, &ss];
    let want = 4 * (g0.links.len() + arrays.iter().map(|a| a.len()).sum::<usize>()) as u64;
    assert_eq!(cpu.state_bytes(), want);
    assert_eq!(vk.state_bytes(), want);

    let g = alphasurf::grid::Grid::sphere(32, [0.0; 3], [1.0; 3], 1.0, 0.1);
    let (vk, cpu) = (
        VulkanPlenoxels::new(gpu, g.clone()).unwrap(),
        CpuPlenoxels::new(g.clone()),
    );
    let [sd, ss] = cpu.optimizer_state().unwrap();
    let arrays = [&g.density, &g.sh, &sd, &ss];
    let want = 4 * (g.links.len() + arrays.iter().map(|a| a.len()).sum::<usize>()) as u64;
    assert_eq!(cpu.state_bytes(), want);
    assert_eq!(vk.state_bytes(), want);
}
