//! The two macros the shared descriptions (`consts.rs`, `buffers.rs`) are written in. This is
//! their crate expansion; `build.rs` defines its own (`build/abi.rs`), which reads the same
//! descriptions into the generated GLSL header and the layout checks against the SPIR-V.

/// `NAME: type = value;` entries → `pub const` items.
macro_rules! abi_consts {
    ($($(#[$meta:meta])* $name:ident: $ty:ty = $value:expr;)*) => {
        $($(#[$meta])* pub const $name: $ty = $value;)*
    };
}

/// Buffer structs → `#[repr(C)]` `Pod` structs (the GLSL declares them with scalar layout; the
/// build checks every member offset against the SPIR-V of each kernel that uses one).
/// `counters Name / Means { a, b, }` declares `u32` counters that also get `NAMES`, `named()` and
/// a wrapping `+` (the kernels sum them with u32 atomics), and, when `/ Means` is given, a struct
/// `Means` of `f64` per-item means with the same field names (`add` a `Name`, then `scaled`).
macro_rules! abi_structs {
    (@item $(#[$meta:meta])* struct $name:ident [] {
        $($(#[$fmeta:meta])* $field:ident: $fty:ty,)*
    }) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            $($(#[$fmeta])* pub $field: $fty,)*
        }
    };
    (@item $(#[$meta:meta])* counters $name:ident [$($means:ident)?] {
        $($(#[$fmeta:meta])* $field:ident,)*
    }) => {
        abi_structs!(@item $(#[$meta])* struct $name [] { $($(#[$fmeta])* $field: u32,)* });
        impl $name {
            /// The counters' names, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$(stringify!($field)),*];
            /// Each counter with its name, in declaration order.
            pub fn named(&self) -> Vec<(&'static str, u32)> {
                vec![$((stringify!($field), self.$field)),*]
            }
        }
        impl std::ops::AddAssign for $name {
            fn add_assign(&mut self, o: Self) {
                $(self.$field = self.$field.wrapping_add(o.$field);)*
            }
        }
        impl std::ops::Add for $name {
            type Output = Self;
            fn add(mut self, o: Self) -> Self {
                self += o;
                self
            }
        }
        abi_structs!(@means $name [$($means)?] { $($field,)* });
    };
    (@means $name:ident [] { $($field:ident,)* }) => {};
    (@means $name:ident [$means:ident] { $($field:ident,)* }) => {
        #[doc = concat!("Sums, then means, of [`", stringify!($name), "`] (same fields).")]
        #[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
        pub struct $means {
            $(pub $field: f64,)*
        }
        impl $means {
            /// Adds each counter of `c`.
            pub fn add(&mut self, c: &$name) {
                $(self.$field += c.$field as f64;)*
            }
            /// Every field times `k` (sums → means).
            pub fn scaled(self, k: f64) -> Self {
                Self { $($field: self.$field * k,)* }
            }
            /// Each field with its name, in declaration order.
            pub fn named(&self) -> Vec<(&'static str, f64)> {
                vec![$((stringify!($field), self.$field)),*]
            }
        }
    };
    ($($(#[$meta:meta])* $kind:ident $name:ident $(/ $means:ident)? { $($body:tt)* })*) => {
        $(abi_structs!(@item $(#[$meta])* $kind $name [$($means)?] { $($body)* });)*
    };
}
