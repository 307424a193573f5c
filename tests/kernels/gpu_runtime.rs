//! The Vulkan runtime itself: buffers above maxStorageBufferRange, batching many dispatches,
//! timestamps, push-constant checks, leak accounting, and silence of the validation layer.

use alphasurf::check::fill_pattern;
use alphasurf::gpu::test_gpu;
use alphasurf::kernels::{self, fill_pattern::Push};

fn assert_validation_clean() {
    let msgs = test_gpu().validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

#[test]
fn buffer_larger_than_max_storage_buffer_range() {
    let gpu = test_gpu();
    let range = gpu.info().max_storage_buffer_range as usize;
    // 160 MiB, or 32 MiB past the device's limit when that is larger.
    let bytes = (160usize << 20).max(range + (32 << 20));
    let row = fill_pattern::check_n(gpu, 7, bytes / 4).unwrap();
    assert!(row.pass, "{row:?}");
    assert!(
        bytes > range,
        "test buffer must exceed maxStorageBufferRange"
    );
    assert_validation_clean();
}

#[test]
fn many_dispatches_in_one_batch_are_ordered_and_timed() {
    let gpu = test_gpu();
    let n = 4096u32;
    let buf = gpu.zeros::<u32>(n as usize).unwrap();
    let mut b = gpu.batch().unwrap();
    // Each dispatch overwrites the previous one; only ordering makes the last seed win.
    for seed in 0..50u32 {
        let push = Push {
            dst: buf.address(),
            n,
            seed,
        };
        b.dispatch_1d(&kernels::fill_pattern::INFO, &push, n)
            .unwrap();
    }
    let times = b.submit().unwrap();
    assert_eq!(times.dispatches.len(), 50);
    assert!(times.kernel_ns("fill_pattern") > 0.0);
    let got: Vec<u32> = buf.download().unwrap();
    let mut want = vec![0u32; n as usize];
    alphasurf::cpu::fill_pattern(&mut want, 49);
    assert_eq!(got, want);
    assert_validation_clean();
}

#[test]
fn dispatch_over_many_workgroup_rows() {
    // More than 32768 workgroups along x wraps into y; every element must still be written once.
    let gpu = test_gpu();
    let n = 256 * 32768 + 1000;
    let row = fill_pattern::check_n(gpu, 3, n).unwrap();
    assert!(row.pass, "{row:?}");
}

#[test]
fn push_constant_size_mismatch_is_an_error() {
    let gpu = test_gpu();
    let mut b = gpu.batch().unwrap();
    let err = b
        .dispatch_1d(&kernels::fill_pattern::INFO, &[0u32; 3], 1)
        .unwrap_err();
    assert!(err.to_string().contains("push constants"), "{err}");
    drop(b);
    assert_validation_clean();
}

/// A kernel handed a buffer that is dropped before the batch runs would write memory another
/// buffer may own by then (a parity row once did, through a temporary, and corrupted a row
/// running beside it): recording a freed address is an error, and so is submitting a batch
/// whose buffer was dropped after recording.
#[test]
fn freed_buffer_address_is_refused_when_recorded_and_when_submitted() {
    // A context of its own: on the shared one, a buffer of a test running beside this one may
    // take the freed address.
    let gpu = &alphasurf::gpu::Gpu::new(&Default::default()).unwrap();
    let n = 64u32;
    let push = |dst| Push { dst, n, seed: 1 };
    let freed = gpu.zeros::<u32>(n as usize).unwrap().address();
    let mut b = gpu.batch().unwrap();
    let err = b
        .dispatch_1d(&kernels::fill_pattern::INFO, &push(freed), n)
        .unwrap_err();
    assert!(err.to_string().contains("live buffer"), "{err}");
    drop(b);

    let buf = gpu.zeros::<u32>(n as usize).unwrap();
    let mut b = gpu.batch().unwrap();
    // An address inside the buffer is live too.
    b.dispatch_1d(
        &kernels::fill_pattern::INFO,
        &push(buf.address() + 4),
        n - 1,
    )
    .unwrap();
    drop(buf);
    // A buffer of the same size, which the allocator may place at the same address: still the
    // dropped buffer's dispatch.
    let _same_size = gpu.zeros::<u32>(n as usize).unwrap();
    let err = b.submit().unwrap_err();
    assert!(err.to_string().contains("fill_pattern"), "{err}");

    let kept = gpu.zeros::<u32>(n as usize).unwrap();
    let mut b = gpu.batch().unwrap();
    b.dispatch_1d(&kernels::fill_pattern::INFO, &push(kept.address()), n)
        .unwrap();
    b.submit().unwrap();
    let mut want = vec![0u32; n as usize];
    alphasurf::cpu::fill_pattern(&mut want, 1);
    assert_eq!(kept.download::<u32>().unwrap(), want);
}

#[test]
fn upload_download_roundtrip_and_leak_accounting() {
    let gpu = test_gpu();
    let data: Vec<f32> = (0..1000).map(|i| i as f32 * 0.5 - 3.0).collect();
    let before = gpu.live_buffers();
    {
        let buf = gpu.upload(&data).unwrap();
        assert!(gpu.live_buffers() > before || before > 0);
        let back: Vec<f32> = buf.download().unwrap();
        assert_eq!(back, data);
        assert_ne!(buf.address(), 0);
    }
    // Other tests run concurrently on the shared context, so compare with a fresh context too.
    let own = alphasurf::gpu::Gpu::new(&Default::default()).unwrap();
    {
        let _a = own.zeros::<f32>(10).unwrap();
        let _b = own.upload(&data).unwrap();
        assert_eq!(own.live_buffers(), 2);
    }
    assert_eq!(own.live_buffers(), 0, "buffers leaked");
}

#[test]
fn kernel_table_matches_sources() {
    let names: Vec<&str> = kernels::ALL.iter().map(|k| k.name).collect();
    let mut files: Vec<String> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/glsl"))
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "comp").then(|| p.file_stem().unwrap().to_string_lossy().into())
        })
        .collect();
    files.sort();
    assert_eq!(names, files);
    for k in kernels::ALL {
        assert_eq!(k.spirv[0], 0x0723_0203, "{}: not SPIR-V", k.name);
        assert!(k.local_size.iter().all(|&s| s >= 1));
        assert!(
            alphasurf::check::rows().iter().any(|(n, _)| *n == k.name),
            "{} has no parity check",
            k.name
        );
    }
}

#[test]
fn staging_path_round_trips_like_a_discrete_gpu() {
    // Force the copies through staging buffers, as on a GPU whose device memory is not mappable.
    let gpu = alphasurf::gpu::Gpu::new(&alphasurf::gpu::GpuOptions {
        validation: true,
        force_staging: true,
        ..Default::default()
    })
    .unwrap();
    let data: Vec<u32> = (0..100_003u32)
        .map(|i| i.wrapping_mul(2_654_435_761))
        .collect();
    let buf = gpu.upload(&data).unwrap();
    assert_eq!(buf.download::<u32>().unwrap(), data);
    assert_eq!(
        buf.download_range::<u32>(777, 1000).unwrap(),
        &data[777..1777]
    );
    // A kernel writes through the device address; the result comes back through staging.
    let row = fill_pattern::check_n(&gpu, 9, 300_000).unwrap();
    assert!(row.pass, "{row:?}");
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
    drop(buf);
    assert_eq!(gpu.live_buffers(), 0);
}

#[test]
fn batches_recorded_on_several_threads_at_once() {
    // Each batch owns its command pool, so concurrent recording is legal (validation checks it).
    let gpu = test_gpu();
    std::thread::scope(|s| {
        for t in 0..4u64 {
            s.spawn(move || {
                for i in 0..10 {
                    let row = fill_pattern::check_n(gpu, t * 100 + i, 10_000).unwrap();
                    assert!(row.pass, "{row:?}");
                }
            });
        }
    });
    assert_validation_clean();
}
