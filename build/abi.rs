//! The build's expansion of the shared descriptions in `src/abi/` (the crate's is
//! `src/abi/macros.rs`): the same constants and `#[repr(C)]` structs, written out as the GLSL
//! header `abi.glsl`, and each struct's layout for the check against the kernels' SPIR-V.

use std::fmt::Write as _;

/// `NAME: type = value;` entries → the constants, and `glsl()` declaring them.
macro_rules! abi_consts {
    ($($(#[$meta:meta])* $name:ident: $ty:ty = $value:expr;)*) => {
        $($(#[$meta])* pub const $name: $ty = $value;)*
        /// The GLSL `const` declarations of every entry.
        pub fn glsl(out: &mut String) {
            $(crate::abi::GlslConst::declare(&$name, stringify!($name), out);)*
        }
    };
}

/// Buffer structs → the `#[repr(C)]` struct (for its offsets) and `layouts()`.
macro_rules! abi_structs {
    (@item struct $name:ident { $($(#[$fmeta:meta])* $field:ident: $fty:ty,)* }) => {
        #[allow(dead_code)]
        #[repr(C)]
        pub struct $name { $(pub $field: $fty,)* }
        /// A member of a struct declared after this one.
        impl crate::abi::GlslType for $name {
            fn declare(name: &str) -> String {
                format!("{} {name}", stringify!($name))
            }
        }
        impl $name {
            fn layout(counters: bool) -> crate::abi::Layout {
                crate::abi::Layout {
                    name: stringify!($name),
                    size: std::mem::size_of::<$name>() as u32,
                    counters,
                    members: vec![$(crate::abi::LayoutMember {
                        name: stringify!($field),
                        offset: std::mem::offset_of!($name, $field) as u32,
                        glsl: <$fty as crate::abi::GlslType>::declare(stringify!($field)),
                    }),*],
                }
            }
        }
    };
    (@item counters $name:ident { $($(#[$fmeta:meta])* $field:ident,)* }) => {
        abi_structs!(@item struct $name { $($field: u32,)* });
    };
    ($($(#[$meta:meta])* $kind:ident $name:ident $(/ $means:ident)? { $($body:tt)* })*) => {
        $(abi_structs!(@item $kind $name { $($body)* });)*
        /// Every struct's layout, in declaration order.
        pub fn layouts() -> Vec<crate::abi::Layout> {
            vec![$($name::layout(stringify!($kind) == "counters")),*]
        }
    };
}

/// A constant's GLSL declaration.
pub trait GlslConst {
    fn glsl_type() -> String;
    fn glsl_value(&self) -> String;
    fn declare(&self, name: &str, out: &mut String) {
        let ty = Self::glsl_type();
        let (ty, dims) = ty
            .split_once('[')
            .map_or((ty.as_str(), String::new()), |(t, d)| (t, format!("[{d}")));
        writeln!(out, "const {ty} {name}{dims} = {};", self.glsl_value()).unwrap();
    }
}

impl GlslConst for u32 {
    fn glsl_type() -> String {
        "uint".into()
    }
    fn glsl_value(&self) -> String {
        format!("{self}u")
    }
}

impl GlslConst for usize {
    fn glsl_type() -> String {
        "uint".into()
    }
    fn glsl_value(&self) -> String {
        let v = u32::try_from(*self).expect("a usize constant must fit a GLSL uint");
        format!("{v}u")
    }
}

impl GlslConst for f32 {
    fn glsl_type() -> String {
        "float".into()
    }
    /// The shortest literal that gives this f32 exactly. glslang reads a literal as a double and
    /// rounds that to float: when the shortest f32 digits would round twice to another value,
    /// the f64 digits of the value (exact in a double) are written instead.
    fn glsl_value(&self) -> String {
        assert!(
            self.is_finite(),
            "GLSL constants must be finite, got {self}"
        );
        let short = format!("{self:?}");
        let s = if short.parse::<f64>().unwrap() as f32 == *self {
            short
        } else {
            format!("{:?}", *self as f64)
        };
        assert!(s.contains(['.', 'e']), "float literal {s} needs a point");
        s
    }
}

impl<T: GlslConst, const N: usize> GlslConst for [T; N] {
    fn glsl_type() -> String {
        format!("{}[{N}]", T::glsl_type())
    }
    fn glsl_value(&self) -> String {
        let items: Vec<String> = self.iter().map(T::glsl_value).collect();
        format!("{}({})", Self::glsl_type(), items.join(", "))
    }
}

/// A struct member's GLSL declaration (scalar layout: arrays of 2 to 4 become vectors).
pub trait GlslType {
    fn declare(name: &str) -> String;
}

/// A GLSL scalar and the prefix of its vectors.
pub trait GlslScalar {
    const NAME: &'static str;
    const VEC: &'static str;
}

impl GlslScalar for f32 {
    const NAME: &'static str = "float";
    const VEC: &'static str = "vec";
}
impl GlslScalar for u32 {
    const NAME: &'static str = "uint";
    const VEC: &'static str = "uvec";
}
impl GlslScalar for i32 {
    const NAME: &'static str = "int";
    const VEC: &'static str = "ivec";
}

impl<T: GlslScalar> GlslType for T {
    fn declare(name: &str) -> String {
        format!("{} {name}", T::NAME)
    }
}

impl<T: GlslScalar, const N: usize> GlslType for [T; N] {
    fn declare(name: &str) -> String {
        match N {
            2..=4 => format!("{}{N} {name}", T::VEC),
            _ => format!("{} {name}[{N}]", T::NAME),
        }
    }
}

/// One member of a buffer struct.
pub struct LayoutMember {
    pub name: &'static str,
    /// Byte offset in the `#[repr(C)]` struct.
    pub offset: u32,
    /// GLSL declaration (`vec3 scale`).
    pub glsl: String,
}

/// A buffer struct as the Rust side lays it out.
pub struct Layout {
    pub name: &'static str,
    pub size: u32,
    pub members: Vec<LayoutMember>,
    /// All `u32` counters: also a zero constant and a subgroup-reduced atomic add.
    pub counters: bool,
}

impl Layout {
    /// `TrainCounts` → `TRAIN_COUNTS`.
    fn upper_snake(&self) -> String {
        let mut s = String::new();
        for (i, c) in self.name.chars().enumerate() {
            if c.is_uppercase() && i > 0 {
                s.push('_');
            }
            s.push(c.to_ascii_uppercase());
        }
        s
    }

    /// The struct, a `<Name>Buf` buffer reference to an array of it and, for counters,
    /// `<NAME>_ZERO` and `<NAME>_SUBGROUP_ADD(dst, c)` (adds c summed over the subgroup into the
    /// struct `dst` in a buffer, one atomic per counter; needs the subgroup arithmetic extension
    /// where used).
    fn glsl(&self, out: &mut String) {
        writeln!(out, "struct {} {{", self.name).unwrap();
        for m in &self.members {
            writeln!(out, "    {};", m.glsl).unwrap();
        }
        writeln!(out, "}};").unwrap();
        writeln!(
            out,
            "layout(buffer_reference, scalar, buffer_reference_align = 4) buffer {0}Buf {{ {0} v[]; }};",
            self.name
        )
        .unwrap();
        if self.counters {
            let upper = self.upper_snake();
            let zeros = vec!["0u"; self.members.len()].join(", ");
            writeln!(out, "#define {upper}_ZERO {}({zeros})", self.name).unwrap();
            write!(
                out,
                "#define {upper}_SUBGROUP_ADD(dst, c) {{ \\\n    {} s_; \\\n",
                self.name
            )
            .unwrap();
            for m in &self.members {
                writeln!(out, "    s_.{0} = subgroupAdd((c).{0}); \\", m.name).unwrap();
            }
            writeln!(out, "    if (subgroupElect()) {{ \\").unwrap();
            for m in &self.members {
                writeln!(out, "        atomicAdd((dst).{0}, s_.{0}); \\", m.name).unwrap();
            }
            writeln!(out, "    }} \\\n}}").unwrap();
        }
    }
}

/// The generated header: every constant, then every struct.
pub fn header(consts: impl Fn(&mut String), layouts: &[Layout]) -> String {
    let mut out = String::from(
        "// @generated by build.rs from src/abi/consts.rs and src/abi/buffers.rs — do not edit.\n\
         // Included by common.glsl (after the buffer-reference extensions).\n\
         #ifndef ABI_GLSL\n#define ABI_GLSL\n",
    );
    consts(&mut out);
    for l in layouts {
        l.glsl(&mut out);
    }
    out.push_str("#endif\n");
    out
}
