//! Twin of `glsl/optim_args.comp`.

use crate::abi::consts::DISPATCH_ROW_GROUPS;

/// Twin of `optim_args.comp`: indirect dispatch arguments for `count` touched vertices.
pub fn optim_args(count: u32) -> [u32; 3] {
    let groups = count.div_ceil(64);
    let gx = groups.min(DISPATCH_ROW_GROUPS);
    [gx, if gx == 0 { 0 } else { groups.div_ceil(gx) }, 1]
}
