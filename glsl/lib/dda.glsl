// dda.glsl — ray/box clipping (slab method) and the DDA cell walk over an N³-vertex grid
// (method.md §3.2, §5). Rust twin: src/math/dda.rs, same arithmetic bit for bit.
//
// Grid: N³ vertices at integer coordinates 0..N-1; cell l ∈ [0, N-2]³ is the cube [l, l+1].
// The ray is o + t·d in grid units (d need not be unit; use ray_unit() so t is in voxels).
// Every plane crossing is computed as (k − o)·(1/d), one rounding per operation, the same
// formula for the box faces and the interior planes: ties between axes are then exact whenever
// the crossings are, and the box exit coincides with the last plane crossing.
// Tie rules: a coordinate that is an exact integer at the entry picks the cell the ray moves
// toward; a zero direction component picks floor(x) (N-2 on the outer face x = N-1); through an
// edge or corner all tied axes step at once; zero-length pieces are dropped.
#ifndef DDA_GLSL
#define DDA_GLSL

// DDA_BIG (infinity), DDA_TINY (smaller direction components count as zero, denormal-safe on
// every device), DDA_HUGE (a ray with a larger direction component misses: no subnormal t, which
// some devices flush to zero), DDA_SPLIT_MAX and DDA_HASH0: src/abi/consts.rs (abi.glsl).

// Division and sqrt are not correctly rounded on every device (Vulkan allows 2.5 ulp for x/y, and
// sqrt inherits the error of 1/inversesqrt), and fma() need not be fused (lavapipe's is a multiply
// then an add): a DDA whose 1/d is one ulp off on a GPU takes another branch than the twin
// wherever two plane crossings tie or nearly tie. dda_rcp and dda_sqrt round correctly from any
// start within a few ulps using only multiplies, adds and comparisons, which every device rounds
// correctly (`precise`: no contraction). Domain: normal inputs with normal results (the DDA keeps
// its direction components in [DDA_TINY, DDA_HUGE)).

// The float adjacent to y > 0 on the side `up` (one step of its bit pattern).
float dda_adjacent(float y, bool up) {
    return uintBitsToFloat(floatBitsToUint(y) + (up ? 1u : 0xffffffffu));
}

// The exact product a·b = p + q (Dekker's product with Veltkamp's split, 4097 = 2^12 + 1).
void dda_two_prod(float a, float b, out float p, out float q) {
    precise float pp = a * b;
    precise float ta = 4097.0 * a;
    precise float ah = ta - (ta - a);
    precise float al = a - ah;
    precise float tb = 4097.0 * b;
    precise float bh = tb - (tb - b);
    precise float bl = b - bh;
    precise float qq = (((ah * bh - pp) + ah * bl) + al * bh) + al * bl;
    p = pp;
    q = qq;
}

// c − a·b, exact when the result is representable (c − p is exact by Sterbenz for a·b ≈ c).
float dda_residual(float c, float a, float b) {
    float p, q;
    dda_two_prod(a, b, p, q);
    precise float r = (c - p) - q;
    return r;
}

// Correctly rounded 1/x. One Newton step makes y faithful; then 1 − b·y is representable, so
// exact, as it is for the neighbour z across 1/b, and the nearer of the two has the smaller
// residual (no ties: 1/b is never a midpoint).
float dda_rcp(float x) {
    float b = abs(x);
    float y0 = 1.0 / b;
    float e0 = dda_residual(1.0, b, y0);
    precise float y = y0 + y0 * e0;
    float e = dda_residual(1.0, b, y);
    float z = dda_adjacent(y, e > 0.0);
    float ez = dda_residual(1.0, b, z);
    float r = e != 0.0 && abs(ez) < abs(e) ? z : y;
    return x < 0.0 ? -r : r;
}

// Correctly rounded sqrt(x), x > 0. One Newton step makes s faithful; r = x − s² is then exact.
// The neighbour z = s + u across sqrt(x) is nearer iff x lies beyond the midpoint's square
// s² + s·u + u²/4; r and s·u are multiples of u², so that is the sign of r − s·u (> 0 for u > 0,
// ≤ 0 for u < 0).
float dda_sqrt(float x) {
    float s0 = sqrt(x);
    float r0 = dda_residual(x, s0, s0);
    precise float s = s0 + r0 * (0.5 / s0);
    float r = dda_residual(x, s, s);
    bool up = r > 0.0;
    float z = dda_adjacent(s, up);
    precise float u = z - s;
    precise float su = s * u;
    precise float dm = r - su;
    bool take = r != 0.0 && (up ? dm > 0.0 : dm <= 0.0);
    return take ? z : s;
}

// d / |d| (|d|² as plain products and sums: identical on every device).
vec3 ray_unit(vec3 d) {
    precise float l2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    float r = dda_rcp(dda_sqrt(l2));
    precise vec3 u = d * r;
    return u;
}

// Flushes tiny components to zero (applied to o and d: denormals read alike on every device).
vec3 dda_flush(vec3 d) {
    return mix(d, vec3(0.0), lessThan(abs(d), vec3(DDA_TINY)));
}

// 1/d per axis, correctly rounded (dda_rcp); 1 where d == 0 (those axes never use it) or where
// |d| ≥ DDA_HUGE (those rays miss).
vec3 dda_inv(vec3 d) {
    vec3 x = mix(d, vec3(1.0), equal(d, vec3(0.0)));
    x = mix(x, vec3(1.0), greaterThanEqual(abs(d), vec3(DDA_HUGE)));
    return vec3(dda_rcp(x.x), dda_rcp(x.y), dda_rcp(x.z));
}

// Slab clip of o + t·d against [lo, hi]: (t_enter, t_exit) with t_enter = max(slab entries, t_min).
// Hit iff t_enter < t_exit (a ray grazing an edge or corner in one point misses). A zero direction
// component with o outside that slab misses; inside (faces included) it adds no constraint. A
// zero direction vector, a NaN or infinite component in o or d, or a component of d with magnitude
// ≥ DDA_HUGE, misses.
vec2 ray_box(vec3 o, vec3 d, vec3 lo, vec3 hi, float t_min) {
    o = dda_flush(o);
    d = dda_flush(d);
    vec3 inv = dda_inv(d);
    precise vec3 ta = (lo - o) * inv;
    precise vec3 tb = (hi - o) * inv;
    float t0 = t_min;
    float t1 = DDA_BIG;
    for (int a = 0; a < 3; a++) {
        bool inside = o[a] >= lo[a] && o[a] <= hi[a];
        float tn = d[a] == 0.0 ? (inside ? -DDA_BIG : DDA_BIG) : min(ta[a], tb[a]);
        float tf = d[a] == 0.0 ? (inside ? DDA_BIG : -DDA_BIG) : max(ta[a], tb[a]);
        t0 = max(t0, tn);
        t1 = min(t1, tf);
    }
    if (t1 == DDA_BIG) t1 = -DDA_BIG;  // zero direction: miss
    bool finite = all(lessThan(abs(o), vec3(DDA_BIG))) && all(lessThan(abs(d), vec3(DDA_HUGE)));
    if (!finite) {  // NaN, infinite or huge input: miss
        t0 = DDA_BIG;
        t1 = -DDA_BIG;
    }
    return vec2(t0, t1);
}

// Walk state: init with dda_init, then call dda_next until it returns false.
struct Dda {
    vec3 o;       // origin
    vec3 inv;     // 1/d (1 on zero axes, unused)
    ivec3 cell;   // current cell
    ivec3 step;   // -1, 0 or +1 per axis
    vec3 t_next;  // t of the next plane crossing per axis (DDA_BIG on zero axes)
    float t;      // entry t of the current cell
    float t_end;  // box exit
};

// Starts a walk over the cells of an n³-vertex grid (clip box [0, n-1]³) from t_min on.
Dda dda_init(vec3 o, vec3 d, int n, float t_min) {
    Dda s;
    o = dda_flush(o);
    d = dda_flush(d);
    vec2 tt = ray_box(o, d, vec3(0.0), vec3(float(n - 1)), t_min);
    bvec3 zero = equal(d, vec3(0.0));
    s.o = o;
    s.inv = dda_inv(d);
    s.step = ivec3(sign(d));
    s.t = tt.x;
    s.t_end = tt.y;
    ivec3 up = max(s.step, ivec3(0));
    // Estimate the entry cell from the entry point, then settle it with the plane crossings
    // themselves: the next plane must lie beyond t, the previous one at or before t. The entry
    // point is o + (t·d as an exact product p + q), so no compiler's contraction changes it (when
    // o and t·d nearly cancel, a fused and an unfused o + t·d can lie several cells apart). Past
    // DDA_SPLIT_MAX the split would overflow: there the plain product (no cell is resolved anyway).
    vec3 ph, pl;
    dda_two_prod(tt.x, d.x, ph.x, pl.x);
    dda_two_prod(tt.x, d.y, ph.y, pl.y);
    dda_two_prod(tt.x, d.z, ph.z, pl.z);
    if (!(abs(tt.x) < DDA_SPLIT_MAX)) {
        precise vec3 pp = tt.x * d;
        ph = pp;
        pl = vec3(0.0);
    }
    precise vec3 p = (o + ph) + pl;
    ivec3 c = ivec3(floor(clamp(p, vec3(-1.0), vec3(float(n)))));
    precise vec3 tn = (vec3(c + up) - o) * s.inv;
    c += ivec3(lessThanEqual(tn, vec3(s.t))) * s.step;
    precise vec3 tp = (vec3(c + 1 - up) - o) * s.inv;
    c -= ivec3(greaterThan(tp, vec3(s.t))) * s.step;
    s.cell = clamp(c, ivec3(0), ivec3(n - 2));
    precise vec3 tx = (vec3(s.cell + up) - o) * s.inv;
    s.t_next = mix(tx, vec3(DDA_BIG), zero);
    if (!(tt.x < tt.y)) {  // miss: a state whose first dda_next ends the walk at once
        s.t_next = vec3(DDA_BIG);
        s.t = -DDA_BIG;
        s.t_end = -DDA_BIG;
    }
    return s;
}

// One cell of a walk and the t range [t0, t1] the ray spends in it (dda_next's out parameters;
// twin: math::dda::DdaPiece).
struct DdaPiece {
    ivec3 cell; // cell index l ∈ [0, n−2]³
    float t0;   // entry t
    float t1;   // exit t
};

// Next cell of the walk, front to back: its index and the t range [t0, t1] (t1 > t0).
// Returns false when the walk is over. Written as one do-while (no return inside the loop), which
// llvmpipe runs faster than a while loop with a return inside (docs/tuning.md); past the end a
// call takes one zero-length step and returns false.
bool dda_next(inout Dda s, out ivec3 cell, out float t0, out float t1) {
    do {
        float tm = min(min(s.t_next.x, s.t_next.y), min(s.t_next.z, s.t_end));
        cell = s.cell;
        t0 = s.t;
        t1 = tm;
        bvec3 hit = equal(s.t_next, vec3(tm));
        s.cell += ivec3(hit) * s.step;
        precise vec3 tx = (vec3(s.cell + max(s.step, ivec3(0))) - s.o) * s.inv;
        s.t_next = mix(s.t_next, tx, hit);
        s.t = tm;
    } while (!(t1 > t0) && s.t < s.t_end);
    return t1 > t0;
}

// Linear index of a cell's (0,0,0) corner in the n³ vertex grid, x-major: (x·n + y)·n + z.
uint dda_cell_index(ivec3 c, uint n) {
    return (uint(c.x) * n + uint(c.y)) * n + uint(c.z);
}

// Order-sensitive checksum of a walk (FNV-1a over cell indices); start from DDA_HASH0.
uint dda_hash(uint h, uint idx) {
    return (h ^ idx) * 16777619u;
}

#endif
