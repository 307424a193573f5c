//! A stage-2 training step as an ordered list of typed passes, built and validated once from the
//! step's parameters and the grid; the CPU backend runs each pass's twin, the Vulkan backend
//! records its kernels, both top to bottom. The order: skip structure (when δ may have drifted
//! past its margin) → fused training pass → regularisers (Lδ, TVα, Lα, Ln) → RMSProp →
//! background step (when it is learned).

use super::{batch_loss, BlockRefresh, SurfaceStepParams};
use crate::abi::consts::SURF_MAX_HITS;
use crate::abi::normal_reg::{NormalChunk, NormalPrefix};
use crate::abi::regularisers::DeltaTvChunk;
use crate::abi::regularisers::OpacityChunk;
use crate::abi::regularisers::TvChunk;
use crate::abi::step::RowRange;
use crate::abi::train::BackgroundStep;
use crate::abi::train::SurfaceLoss;
use crate::abi::train::SurfaceRmsProp;
use crate::math::surface::Truncation;
use anyhow::{ensure, Result};

/// One pass of a stage-2 step, with everything it needs besides the backend's buffers.
#[derive(Clone, Copy, Debug)]
pub enum SurfacePass {
    /// Rebuild the skip structure (`surface_blocks`) with δ ranges widened by `margin`.
    Blocks { margin: f32 },
    /// The fused forward/backward pass over the batch (`surface_train`): gradients += data term.
    Train {
        truncation: Truncation,
        stop_thresh: f32,
        loss: SurfaceLoss,
    },
    /// Lδ over its chunk (`surface_delta_tv`).
    DeltaTv(DeltaTvChunk),
    /// TVα on σα over its slot chunk (`tv`).
    OpacityTv(TvChunk),
    /// Lα over its row chunk (`surface_opacity_reg`).
    OpacityLog(OpacityChunk),
    /// Ln1 + Ln2 over the cells of its chunk (`surface_normal_reg_*`).
    Normals(NormalChunk),
    /// RMSProp on the touched groups and the regularisers' rows (`surface_rmsprop`).
    RmsProp(SurfaceRmsProp),
    /// RMSProp on a learned background (`background_step`).
    Background(BackgroundStep),
}

/// What the plan needs to know of the grid a backend holds.
pub struct PlanGrid<'a> {
    pub res: [u32; 3],
    /// Allocated vertices (rows of δ, σα, SH).
    pub rows: u32,
    /// The normal regularisers' per-grid data (chunks are made from it).
    pub normals: &'a NormalPrefix,
    /// Lδ's forward reach in rows (`surface_delta_tv::forward_reach`).
    pub delta_reach: u32,
}

/// The passes of one stage-2 step, in order.
#[derive(Clone, Debug)]
pub struct SurfacePlan {
    passes: Vec<SurfacePass>,
}

impl SurfacePlan {
    /// A training step on `n_rays` rays with `p` on grid `g` (`learned_bg`: the background is
    /// learned). Refuses a truncation parameter or a regulariser chunk that does not fit the grid.
    /// Validation comes first; `refresh` is then asked whether the skip structure must be rebuilt
    /// (and counts it as rebuilt).
    pub fn step(
        p: &SurfaceStepParams,
        g: &PlanGrid,
        n_rays: usize,
        learned_bg: bool,
        refresh: &mut BlockRefresh,
    ) -> Result<Self> {
        check_truncation(p.truncation.a)?;
        let regs = &p.regs;
        let slots: u64 = g.res.iter().map(|&r| r as u64).product();
        if let Some(c) = &regs.delta_tv {
            ensure!(
                c.rows == g.rows && (c.rows == 0 || c.start < c.rows) && c.count <= c.rows,
                "Lδ chunk of {} rows from {} over {} rows on a grid of {} rows",
                c.count,
                c.start,
                c.rows,
                g.rows
            );
        }
        if let Some(c) = &regs.opacity_tv {
            ensure!(
                c.res == g.res && c.channels == 1 && c.start as u64 + c.count as u64 <= slots,
                "TVα chunk of {} slots from {} for a {:?} grid with {} channels on a {:?} grid",
                c.count,
                c.start,
                c.res,
                c.channels,
                g.res
            );
        }
        if let Some(c) = &regs.opacity_log {
            ensure!(
                c.rows == g.rows,
                "Lα chunk over {} rows on a grid of {} rows",
                c.rows,
                g.rows
            );
        }
        let mut normals = regs
            .normals
            .map(|(start, count, l1, l2)| g.normals.chunk(start, count, l1, l2))
            .filter(|c| c.count.min(c.rows) > 0);
        // δ rows the RMSProp range pass covers; the normal regularisers need not flag δ inside
        // them.
        let (delta_rows, inside) =
            delta_rows(regs.delta_tv.as_ref(), g.delta_reach, normals.as_ref());
        if let (Some(c), true) = (&mut normals, inside) {
            c.touch = 0;
        }
        let mut passes = Vec::new();
        if let Some(margin) = refresh.before_pass(p.lr_delta, p.beta) {
            passes.push(SurfacePass::Blocks { margin });
        }
        passes.push(SurfacePass::Train {
            truncation: p.truncation,
            stop_thresh: p.stop_thresh,
            loss: batch_loss(n_rays, p),
        });
        // An empty grid has no row for a regulariser to work on.
        if g.rows > 0 {
            passes.extend(regs.delta_tv.map(SurfacePass::DeltaTv));
            passes.extend(regs.opacity_tv.map(SurfacePass::OpacityTv));
            passes.extend(regs.opacity_log.map(SurfacePass::OpacityLog));
        }
        passes.extend(normals.map(SurfacePass::Normals));
        passes.push(SurfacePass::RmsProp(SurfaceRmsProp {
            lr_delta: p.lr_delta,
            lr_opacity: p.lr_opacity,
            lr_sh: p.lr_sh,
            beta: p.beta,
            eps: p.eps,
            delta_rows,
            opacity_rows: regs.opacity_log.map(|c| c.range()).unwrap_or_default(),
        }));
        // Stage 2 keeps a background's spheres as stage 1 left them: no σ rate.
        let bg = BackgroundStep::when_learned(learned_bg, p.lr_bg, 0.0, 0.0, p.beta, p.eps);
        passes.extend(bg.map(SurfacePass::Background));
        Ok(SurfacePlan { passes })
    }

    /// The data term alone (no regulariser, no update): the skip structure when due, then the
    /// training pass.
    pub fn gradients(
        p: &SurfaceStepParams,
        n_rays: usize,
        refresh: &mut BlockRefresh,
    ) -> Result<Self> {
        check_truncation(p.truncation.a)?;
        let mut passes = Vec::new();
        if let Some(margin) = refresh.before_pass(p.lr_delta, p.beta) {
            passes.push(SurfacePass::Blocks { margin });
        }
        passes.push(SurfacePass::Train {
            truncation: p.truncation,
            stop_thresh: p.stop_thresh,
            loss: batch_loss(n_rays, p),
        });
        Ok(SurfacePlan { passes })
    }

    /// The passes, in the order they run.
    pub fn passes(&self) -> &[SurfacePass] {
        &self.passes
    }
}

fn check_truncation(a: f32) -> Result<()> {
    ensure!(
        a <= SURF_MAX_HITS as f32,
        "truncation parameter a = {a} exceeds the {SURF_MAX_HITS} hits a ray records"
    );
    Ok(())
}

/// The rows whose δ a step's RMSProp updates flagged or not (`SurfaceRmsProp::delta_rows`), and
/// whether the normal regularisers' rows lie within them, so that they need not flag δ (flagging
/// costs one list entry, and one invocation, per vertex): Lδ's window (every row for a whole-grid
/// Lδ; `delta_reach`: its `forward_reach`), widened over the normal chunk's corner window when
/// that starts at the same row (`step_params` draws one start for both), or that corner window
/// alone without Lδ. A row of the range without a δ gradient sees only its RMS state decay.
fn delta_rows(
    delta_tv: Option<&DeltaTvChunk>,
    delta_reach: u32,
    normals: Option<&NormalChunk>,
) -> (RowRange, bool) {
    let mut range = delta_tv.map(|c| c.window(delta_reach));
    let mut inside = false;
    if let Some(n) = normals {
        let corners = n.rows_from_start(n.corner_window);
        match &mut range {
            None => {
                range = Some(corners);
                inside = true;
            }
            Some(r) if r.len == r.rows || r.start == corners.start => {
                r.len = r.len.max(corners.len);
                inside = true;
            }
            Some(_) => {}
        }
    }
    (range.unwrap_or_default(), inside)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::consts::TOUCH_DELTA;
    use crate::abi::regularisers::{delta_tv_chunk, opacity_tv_chunk};
    use crate::grid::row_slots;
    use crate::surface::SurfaceRegs;

    const RES: [u32; 3] = [4, 4, 4];

    /// The normal regularisers' data of a fully allocated 4³ grid (64 rows).
    fn prefix() -> NormalPrefix {
        let links: Vec<i32> = (0..64).collect();
        NormalPrefix::new(&links, &row_slots(&links, 64), RES)
    }

    /// The test grid: every one of its 64 vertices allocated.
    fn grid(normals: &NormalPrefix) -> PlanGrid<'_> {
        PlanGrid {
            res: RES,
            rows: 64,
            normals,
            delta_reach: 16,
        }
    }

    fn params(regs: SurfaceRegs) -> SurfaceStepParams {
        SurfaceStepParams {
            lr_delta: 1e-3,
            lr_opacity: 1e-2,
            lr_sh: 1e-2,
            beta: 0.95,
            eps: 1e-8,
            truncation: 3.0.into(),
            stop_thresh: 1e-4,
            lambda_h: 0.0,
            lambda_c: 0.0,
            regs,
            lr_bg: 1e-2,
        }
    }

    /// Every regulariser on: a whole-grid Lδ, and a normal chunk inside its rows.
    fn all_regs() -> SurfaceRegs {
        SurfaceRegs {
            delta_tv: Some(delta_tv_chunk(RES, 64, 1.0, 1e-3, 7)),
            opacity_tv: Some(opacity_tv_chunk(RES, 0.25, 1e-3, 11)),
            opacity_log: Some(OpacityChunk {
                rows: 64,
                start: 60,
                count: 10,
                lambda: 1e-3,
            }),
            normals: Some((5, 20, 1e-2, 1e-3)),
        }
    }

    fn names(plan: &SurfacePlan) -> Vec<&'static str> {
        plan.passes()
            .iter()
            .map(|p| match p {
                SurfacePass::Blocks { .. } => "blocks",
                SurfacePass::Train { .. } => "train",
                SurfacePass::DeltaTv(_) => "delta_tv",
                SurfacePass::OpacityTv(_) => "opacity_tv",
                SurfacePass::OpacityLog(_) => "opacity_log",
                SurfacePass::Normals(_) => "normals",
                SurfacePass::RmsProp(_) => "rmsprop",
                SurfacePass::Background(_) => "background",
            })
            .collect()
    }

    #[test]
    fn passes_follow_the_step_order() {
        let normals = prefix();
        let g = grid(&normals);
        let mut refresh = BlockRefresh::default();
        let p = params(all_regs());
        let first = SurfacePlan::step(&p, &g, 100, true, &mut refresh).unwrap();
        assert_eq!(
            names(&first),
            [
                "blocks",
                "train",
                "delta_tv",
                "opacity_tv",
                "opacity_log",
                "normals",
                "rmsprop",
                "background"
            ]
        );
        // The masks are fresh: no rebuild until an update has moved δ.
        let second = SurfacePlan::step(&p, &g, 100, false, &mut refresh).unwrap();
        assert_eq!(
            names(&second),
            [
                "train",
                "delta_tv",
                "opacity_tv",
                "opacity_log",
                "normals",
                "rmsprop"
            ]
        );
        // A whole-grid Lδ puts every δ row in the range pass: the normal chunk flags nothing.
        for pass in first.passes() {
            match pass {
                SurfacePass::Normals(c) => assert_eq!(c.touch, 0),
                SurfacePass::RmsProp(h) => {
                    assert_eq!(h.delta_rows, RowRange::all(64));
                    assert_eq!(
                        h.opacity_rows,
                        RowRange {
                            rows: 64,
                            start: 60,
                            len: 10
                        }
                    );
                }
                SurfacePass::Train { loss, .. } => assert_eq!(loss.grad_scale, 2.0 / 300.0),
                _ => {}
            }
        }
        // No regulariser, fixed background: the training pass and RMSProp alone.
        let bare = SurfacePlan::step(
            &params(SurfaceRegs::default()),
            &g,
            100,
            false,
            &mut refresh,
        );
        assert_eq!(names(&bare.unwrap()), ["train", "rmsprop"]);
    }

    #[test]
    fn normal_chunk_outside_the_delta_rows_flags_delta() {
        let normals = prefix();
        let g = grid(&normals);
        let mut regs = all_regs();
        // Lδ over 8 rows from row 40, normals from row 5: disjoint starts.
        regs.delta_tv = Some(DeltaTvChunk {
            rows: 64,
            start: 40,
            count: 8,
            scale: 1e-3,
        });
        let plan = SurfacePlan::step(&params(regs), &g, 10, false, &mut BlockRefresh::default());
        let plan = plan.unwrap();
        let touch = plan.passes().iter().find_map(|p| match p {
            SurfacePass::Normals(c) => Some(c.touch),
            _ => None,
        });
        assert_eq!(touch, Some(TOUCH_DELTA));
    }

    #[test]
    fn invalid_chunks_are_refused_before_the_masks_are_claimed() {
        let normals = prefix();
        let g = grid(&normals);
        let mut refresh = BlockRefresh::default();
        let refused = |regs: SurfaceRegs, a: f32, refresh: &mut BlockRefresh| {
            let p = SurfaceStepParams {
                truncation: a.into(),
                ..params(regs)
            };
            SurfacePlan::step(&p, &g, 10, false, refresh)
                .unwrap_err()
                .to_string()
        };
        let mut regs = all_regs();
        regs.delta_tv = Some(delta_tv_chunk(RES, 63, 1.0, 1e-3, 0));
        assert!(refused(regs, 3.0, &mut refresh).contains("Lδ chunk"));
        let mut regs = all_regs();
        regs.opacity_tv = Some(opacity_tv_chunk([8, 8, 8], 0.1, 1e-3, 0));
        assert!(refused(regs, 3.0, &mut refresh).contains("TVα chunk"));
        let mut regs = all_regs();
        regs.opacity_log = Some(OpacityChunk {
            rows: 65,
            start: 0,
            count: 1,
            lambda: 1.0,
        });
        assert!(refused(regs, 3.0, &mut refresh).contains("Lα chunk over 65 rows"));
        assert!(refused(all_regs(), 9.0, &mut refresh).contains("truncation parameter a = 9"));
        let p = SurfaceStepParams {
            truncation: 9.0.into(),
            ..params(all_regs())
        };
        assert!(SurfacePlan::gradients(&p, 10, &mut refresh).is_err());
        // None of the refusals counted the skip structure as rebuilt.
        let plan = SurfacePlan::step(&params(all_regs()), &g, 10, false, &mut refresh).unwrap();
        assert!(matches!(plan.passes()[0], SurfacePass::Blocks { .. }));
    }
}
