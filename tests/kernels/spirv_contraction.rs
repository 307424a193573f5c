//! Contraction audit of the compiled kernels (issue 21): no decision a kernel takes may depend on
//! a multiply and an add that a driver is free to fuse into one FMA.
//!
//! SPIR-V lets a driver contract `a·b + c` into an FMA unless one of the two instructions carries
//! the `NoContraction` decoration (GLSL `precise`). lavapipe never contracts, NVIDIA's compiler
//! does, and the CPU twins follow lavapipe, so a comparison or a float → int conversion fed by a
//! contractible pair can take another branch, cell or order on such a GPU than in the twin. This
//! test walks the SSA graph of every kernel backwards from each comparison and each float → int
//! conversion (through locals: a load depends on every store to its variable) and fails on any
//! undecorated `OpFMul`/`OpVectorTimesScalar` (or `OpDot`, a fused sum of products) feeding an
//! undecorated `OpFAdd`/`OpFSub` on that path. Values that only reach outputs (colours,
//! gradients) may be contracted: their parity rows compare with tolerances.

use alphasurf::kernels::{KernelInfo, ALL};
use std::collections::{HashMap, HashSet};

const OP_EXT_INST: u16 = 12;
const OP_VECTOR_SHUFFLE: u16 = 79;
const OP_COMPOSITE_EXTRACT: u16 = 81;
const OP_COMPOSITE_INSERT: u16 = 82;
const OP_DECORATE: u16 = 71;
const OP_MEMBER_DECORATE: u16 = 72;
const OP_VARIABLE: u16 = 59;
const OP_LOAD: u16 = 61;
const OP_STORE: u16 = 62;
const OP_ACCESS_CHAIN: u16 = 65;
const OP_IN_BOUNDS_ACCESS_CHAIN: u16 = 66;
const OP_PTR_ACCESS_CHAIN: u16 = 67;
const OP_CONVERT_F_TO_U: u16 = 109;
const OP_CONVERT_F_TO_S: u16 = 110;
const OP_F_NEGATE: u16 = 127;
const OP_F_ADD: u16 = 129;
const OP_F_SUB: u16 = 131;
const OP_F_MUL: u16 = 133;
const OP_VECTOR_TIMES_SCALAR: u16 = 142;
const OP_DOT: u16 = 148;
const OP_COPY_OBJECT: u16 = 83;
const OP_COMPOSITE_CONSTRUCT: u16 = 80;
const DECORATION_NO_CONTRACTION: u32 = 42;

/// One instruction that defines an id: its opcode and the ids it reads.
struct Def {
    op: u16,
    args: Vec<u32>,
}

struct Module {
    defs: HashMap<u32, Def>,
    /// Root variable → values stored into it (through access chains).
    stores: HashMap<u32, Vec<u32>>,
    no_contraction: HashSet<u32>,
    /// Comparisons and float → int conversions.
    sinks: Vec<u32>,
}

/// Opcodes with a result type and a result id (the ones this audit reads; the rest define ids
/// the trace never needs to enter, or none).
fn has_result(op: u16) -> bool {
    // ExtInst; shuffle/construct/extract/insert/copy; conversions; arithmetic; logic, select,
    // comparisons, bit operations; OpPhi.
    matches!(op, OP_EXT_INST | 79..=83 | 109..=124 | 126..=157 | 164..=200 | 245)
}

fn parse(words: &[u32]) -> Module {
    assert_eq!(words[0], 0x0723_0203, "SPIR-V magic");
    let mut m = Module {
        defs: HashMap::new(),
        stores: HashMap::new(),
        no_contraction: HashSet::new(),
        sinks: Vec::new(),
    };
    let mut chain_root: HashMap<u32, u32> = HashMap::new();
    let mut i = 5;
    while i < words.len() {
        let op = (words[i] & 0xffff) as u16;
        let len = (words[i] >> 16) as usize;
        assert!(len > 0, "malformed SPIR-V at word {i}");
        let w = &words[i + 1..i + len];
        match op {
            OP_DECORATE if w[1] == DECORATION_NO_CONTRACTION => {
                m.no_contraction.insert(w[0]);
            }
            OP_DECORATE | OP_MEMBER_DECORATE => {}
            OP_VARIABLE => {
                chain_root.insert(w[1], w[1]);
            }
            OP_ACCESS_CHAIN | OP_IN_BOUNDS_ACCESS_CHAIN | OP_PTR_ACCESS_CHAIN => {
                let root = *chain_root.get(&w[2]).unwrap_or(&w[2]);
                chain_root.insert(w[1], root);
                m.defs.insert(
                    w[1],
                    Def {
                        op,
                        args: w[3..].to_vec(),
                    },
                );
            }
            OP_STORE => {
                let root = *chain_root.get(&w[0]).unwrap_or(&w[0]);
                m.stores.entry(root).or_default().push(w[1]);
            }
            OP_LOAD => {
                let root = *chain_root.get(&w[2]).unwrap_or(&w[2]);
                m.defs.insert(
                    w[1],
                    Def {
                        op,
                        args: vec![root, w[2]],
                    },
                );
            }
            _ if has_result(op) => {
                let args = match op {
                    // set, instruction number, then ids
                    OP_EXT_INST => w[4..].to_vec(),
                    // vector 1, vector 2, then literal components
                    OP_VECTOR_SHUFFLE => w[2..4].to_vec(),
                    // composite, then literal indices
                    OP_COMPOSITE_EXTRACT => w[2..3].to_vec(),
                    // object, composite, then literal indices
                    OP_COMPOSITE_INSERT => w[2..4].to_vec(),
                    _ => w[2..].to_vec(),
                };
                if (180..=191).contains(&op) || op == OP_CONVERT_F_TO_U || op == OP_CONVERT_F_TO_S {
                    m.sinks.push(w[1]);
                }
                m.defs.insert(w[1], Def { op, args });
            }
            _ => {}
        }
        i += len;
    }
    m
}

impl Module {
    fn is_product(&self, id: u32) -> bool {
        self.defs.get(&id).is_some_and(|d| {
            matches!(d.op, OP_F_MUL | OP_VECTOR_TIMES_SCALAR | OP_DOT)
                && !self.no_contraction.contains(&id)
        })
    }

    /// A product reaching `id` through moves that a compiler looks through when it fuses.
    fn product_under(&self, mut id: u32) -> Option<u32> {
        for _ in 0..8 {
            if self.is_product(id) {
                return Some(id);
            }
            match self.defs.get(&id) {
                Some(d)
                    if matches!(
                        d.op,
                        OP_F_NEGATE
                            | OP_COPY_OBJECT
                            | OP_COMPOSITE_EXTRACT
                            | OP_VECTOR_SHUFFLE
                            | OP_COMPOSITE_CONSTRUCT
                    ) && d.args.len() == 1 =>
                {
                    id = d.args[0]
                }
                _ => return None,
            }
        }
        None
    }

    /// Contractible (add, product) pairs on which some decision depends.
    fn contractible_decisions(&self) -> Vec<(u32, u32)> {
        let mut seen = HashSet::new();
        let mut stack = self.sinks.clone();
        let mut found = Vec::new();
        while let Some(id) = stack.pop() {
            if !seen.insert(id) {
                continue;
            }
            if let Some(vals) = self.stores.get(&id) {
                stack.extend(vals);
            }
            let Some(d) = self.defs.get(&id) else {
                continue;
            };
            if matches!(d.op, OP_F_ADD | OP_F_SUB) && !self.no_contraction.contains(&id) {
                for &a in &d.args {
                    if let Some(p) = self.product_under(a) {
                        found.push((id, p));
                    }
                }
            }
            if d.op == OP_DOT && !self.no_contraction.contains(&id) {
                found.push((id, id));
            }
            stack.extend(&d.args);
        }
        found.sort_unstable();
        found.dedup();
        found
    }
}

fn audit(k: &KernelInfo) -> Vec<(u32, u32)> {
    parse(k.spirv).contractible_decisions()
}

#[test]
fn no_decision_depends_on_a_contractible_multiply_add() {
    let mut report = Vec::new();
    for k in ALL {
        let pairs = audit(k);
        if !pairs.is_empty() {
            report.push(format!(
                "{}: {} pairs, e.g. add %{} with product %{}",
                k.name,
                pairs.len(),
                pairs[0].0,
                pairs[0].1
            ));
        }
    }
    assert!(
        report.is_empty(),
        "decisions fed by contractible multiply-adds (mark them `precise`; see the SPIR-V with \
         spirv-dis):\n{}",
        report.join("\n")
    );
}

/// The audit sees a contractible pair that feeds a comparison, and accepts a decorated one: a
/// hand-assembled module `x = a·b + c; x < 0`, with and without `NoContraction` on the add.
#[test]
fn audit_flags_an_undecorated_pair_and_accepts_a_decorated_one() {
    let inst = |op: u16, w: &[u32]| {
        let mut v = vec![((w.len() as u32 + 1) << 16) | op as u32];
        v.extend_from_slice(w);
        v
    };
    // ids: 1 float type, 2 bool type, 3..5 a, b, c (stand-ins), 6 = a·b, 7 = 6 + c, 8 = 7 < c.
    let body = |decorate: bool| {
        let mut w = vec![0x0723_0203, 0x0001_0500, 0, 9, 0];
        if decorate {
            w.extend(inst(OP_DECORATE, &[7, DECORATION_NO_CONTRACTION]));
        }
        w.extend(inst(OP_F_MUL, &[1, 6, 3, 4]));
        w.extend(inst(OP_F_ADD, &[1, 7, 6, 5]));
        w.extend(inst(184, &[2, 8, 7, 5])); // OpFOrdLessThan
        w
    };
    assert_eq!(parse(&body(false)).contractible_decisions(), vec![(7, 6)]);
    assert!(parse(&body(true)).contractible_decisions().is_empty());
}
