//! The learned background on the device: recording its optimiser step (`background_step` for
//! the colour, clamped to [0, 1]; `tv` and `background_spheres_step` for the spheres' texels)
//! and the spheres' buffers, shared by both Vulkan backends.

use super::{address_words, record_tv, Batch, Gpu, GpuBuffer};
use crate::abi::buffers::BackgroundSpheres;
use crate::abi::train::BackgroundStep;
use crate::kernels;
use crate::math::background_msi::SphereTable;
use anyhow::Result;

/// A background's spheres on the device: their shape (with the addresses of the texel values
/// and their gradient, in `shape_buf`), the values, gradient and running averages.
pub struct SphereBuffers {
    pub shape: BackgroundSpheres,
    pub shape_buf: GpuBuffer,
    pub table: GpuBuffer,
    pub grad: GpuBuffer,
    pub avg: GpuBuffer,
    /// The links of the spheres' TV (`BackgroundSpheres::tv_links`).
    pub tv_links: GpuBuffer,
}

impl SphereBuffers {
    /// `t` on `gpu`, gradient zero.
    pub fn upload(gpu: &Gpu, t: &SphereTable) -> Result<Self> {
        let table = gpu.upload_nonempty(&t.table)?;
        let grad = gpu.zeros::<f32>(t.table.len().max(1))?;
        let avg = gpu.upload_nonempty(&t.avg)?;
        let shape = BackgroundSpheres {
            table: address_words(table.address()),
            grad: address_words(grad.address()),
            ..t.shape
        };
        Ok(SphereBuffers {
            shape_buf: gpu.upload(&[shape])?,
            tv_links: gpu.upload_nonempty(&t.shape.tv_links())?,
            shape,
            table,
            grad,
            avg,
        })
    }

    /// The spheres with their running averages, read back (addresses cleared).
    pub fn download(&self) -> Result<SphereTable> {
        let n = self.shape.table_len();
        let (mut table, mut avg) = (self.table.download()?, self.avg.download()?);
        table.truncate(n);
        avg.truncate(n);
        Ok(SphereTable {
            shape: BackgroundSpheres {
                table: [0; 2],
                grad: [0; 2],
                ..self.shape
            },
            table,
            avg,
        })
    }

    /// The gradient of the step so far, read and cleared.
    pub fn take_grad(&self) -> Result<Vec<f32>> {
        let mut g = self.grad.download()?;
        g.truncate(self.shape.table_len());
        self.grad.write(&vec![0f32; g.len().max(1)])?;
        Ok(g)
    }
}

/// Records one optimiser step of the background held in `bg` (a `Background` buffer) and, when
/// they are learned, of its `spheres`: their TV (`tv`, when `s.sphere_tv` > 0; `step` is the
/// step record its push block names, untouched), then their step.
pub fn record_background_step(
    b: &mut Batch,
    bg: &GpuBuffer,
    spheres: Option<&SphereBuffers>,
    step: &GpuBuffer,
    s: &BackgroundStep,
) -> Result<()> {
    b.dispatch_1d(
        &kernels::background_step::INFO,
        &kernels::background_step::Push {
            bg: bg.address(),
            lr: s.lr,
            beta: s.beta,
            eps: s.eps,
            ..Default::default()
        },
        3,
    )?;
    let Some(sp) = spheres.filter(|sp| sp.shape.learn != 0) else {
        return Ok(());
    };
    if s.sphere_tv > 0.0 {
        record_sphere_tv(b, sp, step, s.sphere_tv)?;
    }
    let [lr_sigma, lr_colour] = s.sphere_rates();
    let n = sp.shape.table_len() as u32;
    b.dispatch_1d(
        &kernels::background_spheres_step::INFO,
        &kernels::background_spheres_step::Push {
            spheres: sp.shape_buf.address(),
            avg: sp.avg.address(),
            lr_sigma,
            lr_colour,
            beta: s.beta,
            eps: s.eps,
            n,
            ..Default::default()
        },
        n,
    )
}

/// Records the gradient of the spheres' TV of weight `lambda` added to their gradient (`tv` with
/// `BackgroundSpheres::tv_chunk`'s chunk; `step`: the step record the kernel's push block names,
/// untouched). Twin: `cpu::background_spheres_step::sphere_tv`.
pub fn record_sphere_tv(
    b: &mut Batch,
    sp: &SphereBuffers,
    step: &GpuBuffer,
    lambda: f32,
) -> Result<()> {
    let chunk = sp.shape.tv_chunk(lambda);
    record_tv(b, &sp.tv_links, &sp.table, &sp.grad, step, &chunk)
}
