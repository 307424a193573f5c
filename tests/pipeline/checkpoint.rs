//! svox2 npz import/export and atomic checkpoints: bit-exact round trips, float16 and
//! svox2-style inputs, clear errors on malformed files, and crash safety of the atomic write.

use std::fs;
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use alphasurf::checkpoint::format as checkpoint;
use alphasurf::grid::npz::{self, NpzWriter};
use alphasurf::grid::{Grid, SH_DIM};
use half::f16;
use npyz::WriterBuilder;
use rand::{Rng, SeedableRng};
use serde_json::json;

/// A fresh, empty directory for one test.
fn dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("checkpoint-{name}"));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

/// A non-cubic grid with holes, random data (negative, tiny, subnormal, −0.0 values).
fn random_grid(seed: u64) -> Grid {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let res = [5u32, 7, 3];
    let mut links = vec![-1i32; 5 * 7 * 3];
    let mut n = 0;
    for l in &mut links {
        if rng.random_bool(0.6) {
            *l = n;
            n += 1;
        }
    }
    let mut val = |i: usize| match i % 7 {
        0 => -0.0,
        1 => f32::from_bits(1 + (i as u32 % 100)), // subnormal
        2 => 1e-30,
        _ => rng.random_range(-100.0f32..100.0),
    };
    let density = (0..n as usize).map(&mut val).collect();
    let sh = (0..n as usize * SH_DIM).map(&mut val).collect();
    Grid {
        res,
        center: [0.25, -0.5, 1.0],
        radius: [1.0, 1.5, 0.75],
        links,
        density,
        sh,
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_bit_exact(a: &Grid, b: &Grid) {
    assert_eq!(a.res, b.res);
    assert_eq!(bits(&a.center), bits(&b.center));
    assert_eq!(bits(&a.radius), bits(&b.radius));
    assert_eq!(a.links, b.links);
    assert_eq!(bits(&a.density), bits(&b.density));
    assert_eq!(bits(&a.sh), bits(&b.sh));
}

/// Write an npz by hand with `fill`.
fn write_npz(path: &Path, fill: impl FnOnce(&mut NpzWriter<Cursor<Vec<u8>>>)) {
    let mut w = NpzWriter::new(Cursor::new(Vec::new()));
    fill(&mut w);
    fs::write(path, w.finish().unwrap().into_inner()).unwrap();
}

/// One `.npy` file's bytes.
fn npy_bytes<T: npyz::AutoSerialize + Copy>(shape: &[u64], data: &[T]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut out)
        .begin_nd()
        .unwrap();
    w.extend(data.iter().copied()).unwrap();
    w.finish().unwrap();
    out
}

/// The full error chain of importing `path` as svox2.
fn import_err(path: &Path) -> String {
    format!("{:#}", npz::load_svox2(path).unwrap_err())
}

fn assert_mentions(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "error {msg:?} does not mention {p:?}");
    }
}

/// The svox2 arrays of `g` with one of them replaced (`skip` left out, `extra` added).
fn svox2_with(
    path: &Path,
    g: &Grid,
    skip: &str,
    extra: impl FnOnce(&mut NpzWriter<Cursor<Vec<u8>>>),
) {
    let n = g.allocated() as u64;
    write_npz(path, |w| {
        if skip != "links" {
            w.array("links", &g.res.map(u64::from), &g.links).unwrap();
        }
        if skip != "density_data" {
            w.array("density_data", &[n, 1], &g.density).unwrap();
        }
        if skip != "sh_data" {
            w.array("sh_data", &[n, SH_DIM as u64], &g.sh).unwrap();
        }
        w.array("radius", &[3], &g.radius).unwrap();
        w.array("center", &[3], &g.center).unwrap();
        extra(w);
    });
}

#[test]
fn svox2_roundtrip_is_bit_exact() {
    let d = dir("roundtrip");
    let p = d.join("ckpt.npz");
    let g = random_grid(1);
    npz::save_svox2(&g, &p).unwrap();
    assert_bit_exact(&g, &npz::load_svox2(&p).unwrap());
    let sphere = Grid::sphere(16, [0.1, 0.0, -0.1], [1.0; 3], 0.9, 0.1);
    npz::save_svox2(&sphere, &p).unwrap();
    assert_bit_exact(&sphere, &npz::load_svox2(&p).unwrap());
    assert_eq!(
        fs::read_dir(&d).unwrap().count(),
        1,
        "only ckpt.npz is left"
    );
}

#[test]
fn float16_svox2_with_extra_arrays_and_skip_links() {
    let d = dir("f16");
    let p = d.join("ckpt.npz");
    // 2×2×3 grid; svox2 stores skip distances as negative links after accelerate().
    let links = [0, -1, -3, 1, -2, 2, -100, 3, -1, i32::MIN, 4, -7];
    let n = 5u64;
    let density: Vec<f32> = (0..n).map(|i| i as f32 * 0.5 - 0.25).collect();
    let sh: Vec<f32> = (0..n * 27).map(|i| (i as f32 - 60.0) / 64.0).collect();
    let h = |v: &[f32]| v.iter().map(|&x| f16::from_f32(x)).collect::<Vec<_>>();
    write_npz(&p, |w| {
        w.array("basis_type", &[], &[1i32]).unwrap();
        w.array("links", &[2, 2, 3], &links).unwrap();
        w.array("density_data", &[n, 1], &h(&density)).unwrap();
        w.array("sh_data", &[n, 27], &h(&sh)).unwrap();
        w.array("radius", &[3], &[1.5f64, 1.5, 1.5]).unwrap();
        w.array("center", &[3], &[0.0f64, 0.5, 0.0]).unwrap();
        w.array("background_data", &[2, 4], &[0.5f32; 8]).unwrap();
    });
    let g = npz::load_svox2(&p).unwrap();
    assert_eq!(g.res, [2, 2, 3]);
    assert_eq!(g.links, [0, -1, -1, 1, -1, 2, -1, 3, -1, -1, 4, -1]);
    assert_eq!(g.density, density, "values exact in f16");
    assert_eq!(g.sh, sh);
    assert_eq!((g.radius, g.center), ([1.5; 3], [0.0, 0.5, 0.0]));
    // np.savez_compressed deflates the entries.
    let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, npy) in [
        ("links", npy_bytes(&[2, 2, 3], &links)),
        ("density_data", npy_bytes(&[n, 1], &h(&density))),
        ("sh_data", npy_bytes(&[n, 27], &h(&sh))),
        ("radius", npy_bytes(&[3], &[1.5f32; 3])),
        ("center", npy_bytes(&[3], &[0.0f32, 0.5, 0.0])),
    ] {
        z.start_file(format!("{name}.npy"), opts).unwrap();
        z.write_all(&npy).unwrap();
    }
    fs::write(&p, z.finish().unwrap().into_inner()).unwrap();
    assert_eq!(npz::load_svox2(&p).unwrap(), g);
    // A missing center is svox2's [0, 0, 0]; a missing radius (the grid's extent) is refused.
    for radius in [false, true] {
        write_npz(&p, |w| {
            w.array("links", &[2, 2, 3], &g.links).unwrap();
            w.array("density_data", &[n, 1], &g.density).unwrap();
            w.array("sh_data", &[n, 27], &g.sh).unwrap();
            if radius {
                w.array("radius", &[3], &[1.5f32; 3]).unwrap();
            }
        });
        if radius {
            assert_eq!(npz::load_svox2(&p).unwrap().center, [0.0; 3]);
        } else {
            assert_mentions(&import_err(&p), &["ckpt.npz", "'radius'", "extent"]);
        }
    }
    // Another basis than spherical harmonics (numpy's int64 scalar, as svox2 saves it).
    for (basis, ok) in [(1i64, true), (4, false), (255, false)] {
        svox2_with(&p, &g, "", |w| {
            w.array("basis_type", &[], &[basis]).unwrap()
        });
        match npz::load_svox2(&p) {
            Ok(_) => assert!(ok, "basis {basis} accepted"),
            Err(e) => {
                assert!(!ok, "basis {basis}: {e:#}");
                assert_mentions(&format!("{e:#}"), &["basis_type", "spherical harmonics"]);
            }
        }
    }
}

#[test]
fn damaged_files_get_clear_errors() {
    let d = dir("damaged");
    let p = d.join("ckpt.npz");
    let g = random_grid(2);
    npz::save_svox2(&g, &p).unwrap();
    let good = fs::read(&p).unwrap();

    // Truncated anywhere: the zip directory at the end is gone.
    for cut in [good.len() / 2, good.len() - 10, 3] {
        fs::write(&p, &good[..cut]).unwrap();
        assert_mentions(&import_err(&p), &["ckpt.npz", "not a readable npz"]);
    }
    // Garbage.
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    fs::write(&p, &garbage).unwrap();
    assert_mentions(&import_err(&p), &["ckpt.npz", "not a readable npz"]);
    // A flipped byte inside sh_data's stored data: the CRC catches it.
    let mut flipped = good.clone();
    let at = good.windows(8).position(|w| w == b"sh_data.").unwrap() + 400;
    flipped[at] ^= 0x40;
    fs::write(&p, &flipped).unwrap();
    assert_mentions(&import_err(&p), &["ckpt.npz", "sh_data", "CRC"]);
    // Missing file.
    assert_mentions(&import_err(&d.join("nope.npz")), &["nope.npz"]);

    for missing in ["links", "density_data", "sh_data"] {
        svox2_with(&p, &g, missing, |_| {});
        assert_mentions(&import_err(&p), &["ckpt.npz", "missing array", missing]);
    }
    let n = g.allocated() as u64;
    let res = g.res.map(u64::from);
    // Wrong dtypes.
    write_npz(&p, |w| {
        let links_f: Vec<f32> = g.links.iter().map(|&l| l as f32).collect();
        w.array("links", &res, &links_f).unwrap();
    });
    assert_mentions(&import_err(&p), &["ckpt.npz", "'links'", "int32"]);
    // numpy's default int64 is read where its values fit int32 (svox2's `basis_type`).
    write_npz(&p, |w| {
        let mut links_64: Vec<i64> = g.links.iter().map(|&l| l as i64).collect();
        links_64[0] = 1 << 40;
        w.array("links", &res, &links_64).unwrap();
    });
    assert_mentions(&import_err(&p), &["ckpt.npz", "'links'", "beyond int32"]);
    svox2_with(&p, &g, "density_data", |w| {
        w.array("density_data", &[n, 1], &vec![1i32; n as usize])
            .unwrap();
    });
    assert_mentions(
        &import_err(&p),
        &["ckpt.npz", "'density_data'", "int32", "expected float"],
    );
    // Wrong shapes.
    svox2_with(&p, &g, "sh_data", |w| {
        w.array("sh_data", &[n * 3, 9], &g.sh).unwrap();
    });
    assert_mentions(&import_err(&p), &["ckpt.npz", "'sh_data'", "27"]);
    svox2_with(&p, &g, "density_data", |w| {
        w.array("density_data", &[n], &g.density).unwrap();
    });
    assert_mentions(&import_err(&p), &["ckpt.npz", "'density_data'", "(n, 1)"]);
    svox2_with(&p, &g, "links", |w| {
        w.array("links", &[res[0] * res[1], res[2]], &g.links)
            .unwrap();
    });
    assert_mentions(&import_err(&p), &["ckpt.npz", "'links'", "(X, Y, Z)"]);
    // Link out of range, links sharing a row, non-finite data.
    let mut bad = g.clone();
    *bad.links.iter_mut().find(|l| **l >= 0).unwrap() = n as i32;
    svox2_with(&p, &bad, "", |_| {});
    assert_mentions(&import_err(&p), &["ckpt.npz", "link", "past the"]);
    let mut bad = g.clone();
    let second = bad.links.iter().rposition(|l| *l >= 0).unwrap();
    bad.links[second] = 0;
    svox2_with(&p, &bad, "", |_| {});
    assert_mentions(&import_err(&p), &["ckpt.npz", "links", "two vertices"]);
    let mut bad = g.clone();
    bad.sh[40] = f32::NAN;
    svox2_with(&p, &bad, "", |_| {});
    assert_mentions(
        &import_err(&p),
        &["ckpt.npz", "sh_data", "non-finite", "40"],
    );
    let mut bad = g.clone();
    bad.density[3] = f32::INFINITY;
    svox2_with(&p, &bad, "", |_| {});
    assert_mentions(&import_err(&p), &["ckpt.npz", "density_data", "non-finite"]);
    // An entry whose npy data is shorter than its header says.
    let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default();
    z.start_file("links.npy", opts).unwrap();
    z.write_all(&npy_bytes(&res, &g.links)).unwrap();
    z.start_file("density_data.npy", opts).unwrap();
    z.write_all(&npy_bytes(&[n, 1], &g.density)).unwrap();
    z.start_file("sh_data.npy", opts).unwrap();
    let sh = npy_bytes(&[n, SH_DIM as u64], &g.sh);
    z.write_all(&sh[..sh.len() - 100]).unwrap();
    fs::write(&p, z.finish().unwrap().into_inner()).unwrap();
    assert_mentions(&import_err(&p), &["ckpt.npz", "'sh_data'", "truncated"]);
}

#[test]
fn checkpoint_roundtrip_and_svox2_view() {
    let d = dir("ckpt");
    let p = d.join("step.npz");
    let g = random_grid(3);
    let optim = vec![
        ("rms_density".to_string(), vec![0.5f32; g.allocated()]),
        (
            "rms_sh".to_string(),
            (0..g.sh.len()).map(|i| i as f32).collect(),
        ),
        ("empty".to_string(), vec![]),
    ];
    let meta =
        json!({"step": 1200, "stage": "plenoxels", "config": {"lr": 30.0, "res": [5, 7, 3]}});
    checkpoint::save(&p, &g, &checkpoint::optim_refs(&optim), &meta).unwrap();
    let c = checkpoint::load(&p).unwrap();
    assert_bit_exact(&g, &c.grid);
    assert_eq!(c.optim, optim);
    assert_eq!(c.meta, meta);
    // The same file is a valid svox2 checkpoint.
    assert_bit_exact(&g, &npz::load_svox2(&p).unwrap());
    // A plain svox2 file is not one of ours.
    let s = d.join("svox2.npz");
    npz::save_svox2(&g, &s).unwrap();
    let e = format!("{:#}", checkpoint::load(&s).unwrap_err());
    assert_mentions(
        &e,
        &["svox2.npz", "alphasurf_meta", "not an alphasurf checkpoint"],
    );
    // Bad optimiser names are refused.
    let e = checkpoint::save(&p, &g, &[("a/b", &[])], &meta).unwrap_err();
    assert_mentions(&format!("{e:#}"), &["a/b", "step.npz"]);
}

#[test]
fn atomic_write_survives_interruption() {
    let d = dir("atomic");
    let p = d.join("ckpt.npz");
    let tmp = d.join("ckpt.npz.tmp");
    let g1 = random_grid(4);
    let meta1 = json!({"step": 1});
    checkpoint::save(&p, &g1, &[], &meta1).unwrap();
    assert!(!tmp.exists(), "no .tmp left behind");
    let g2 = random_grid(5);
    let bytes2 = {
        let q = d.join("other.npz");
        checkpoint::save(&q, &g2, &[], &json!({"step": 2})).unwrap();
        let b = fs::read(&q).unwrap();
        fs::remove_file(&q).unwrap();
        b
    };

    // kill -9 mid-write: a half-written .tmp next to the checkpoint. The checkpoint still loads.
    fs::write(&tmp, &bytes2[..bytes2.len() / 2]).unwrap();
    let c = checkpoint::load(&p).unwrap();
    assert_eq!(
        (c.meta.clone(), c.grid.links.clone()),
        (meta1.clone(), g1.links.clone())
    );
    // The next save replaces the stale .tmp and leaves none.
    checkpoint::save(&p, &g2, &[], &json!({"step": 2})).unwrap();
    assert!(!tmp.exists());
    assert_bit_exact(&g2, &checkpoint::load(&p).unwrap().grid);

    // The write cannot happen (the .tmp path is taken by a directory): error, previous intact.
    fs::create_dir(&tmp).unwrap();
    let e = checkpoint::save(&p, &g1, &[], &meta1).unwrap_err();
    assert_mentions(&format!("{e:#}"), &["ckpt.npz.tmp"]);
    fs::remove_dir(&tmp).unwrap();
    assert_bit_exact(&g2, &checkpoint::load(&p).unwrap().grid);

    // A diverged (NaN) grid or optimiser state is refused before anything is written.
    let mut bad = g1.clone();
    bad.density[0] = f32::NAN;
    let e = checkpoint::save(&p, &bad, &[], &meta1).unwrap_err();
    assert_mentions(&format!("{e:#}"), &["ckpt.npz", "non-finite"]);
    let e = checkpoint::save(&p, &g1, &[("rms", &[f32::INFINITY])], &meta1).unwrap_err();
    assert_mentions(&format!("{e:#}"), &["rms", "non-finite"]);
    assert!(!tmp.exists());
    assert_bit_exact(&g2, &checkpoint::load(&p).unwrap().grid);
    assert_eq!(fs::read_dir(&d).unwrap().count(), 1);
}
