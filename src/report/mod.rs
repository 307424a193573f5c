//! PNG figures for `alphasurf demo` and `alphasurf bench time-vs-error`, drawn with the `image`
//! crate only: an RGB [`canvas::Canvas`] with lines, rectangles and a built-in 5×7 bitmap
//! [`font`] (no system fonts, so the figures look the same on every machine), a perceptual
//! [`colormap`] with a colour bar, x–y line and scatter [`plot`]s, an orthographic point-cloud
//! view coloured by a per-point value ([`cloud`]), a shaded view of a triangle mesh ([`mesh`]), side-by-side image panels, and the CSV training
//! log reader ([`log`]).

pub mod canvas;
pub mod cloud;
pub mod colormap;
pub mod font;
pub mod log;
pub mod mesh;
pub mod plot;

pub use canvas::Canvas;
