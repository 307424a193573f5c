// ndc.glsl — a ray of a forward-facing capture carried into normalised device coordinates (the
// map NeRF and svox2 train LLFF scenes in): a point q of the NDC frame (reference camera looking
// down −z) maps to (−sx·q.x/q.z, −sy·q.y/q.z, 1 + 2n/q.z). Rust twin: src/math/ndc.rs.
#ifndef NDC_GLSL
#define NDC_GLSL

// The NDC ray (origin on the near plane z = −1, unit direction; 6 floats as the kernels take a
// ray) of the ray from o along d (the frame; d need not be unit); proj = (near, sx, sy). A ray
// not heading away from the camera plane (d.z ≥ 0 or NaN) → (0, 0, 3) along +z, which meets
// nothing.
void ndc_ray(vec3 o, vec3 d, vec3 proj, out vec3 ro, out vec3 rd) {
    if (!(d.z < 0.0)) {
        ro = vec3(0.0, 0.0, 3.0);
        rd = vec3(0.0, 0.0, 1.0);
        return;
    }
    const float n = proj.x;
    precise float t = -(n + o.z) / d.z;
    precise float ox = fma(t, d.x, o.x) / n;
    precise float oy = fma(t, d.y, o.y) / n;
    precise float rx = d.x / d.z;
    precise float ry = d.y / d.z;
    precise vec3 nd = vec3(-proj.y * (rx + ox), -proj.z * (ry + oy), 2.0);
    precise float len2 = nd.x * nd.x + nd.y * nd.y + nd.z * nd.z;
    precise float inv = 1.0 / sqrt(len2);
    ro = vec3(proj.y * ox, proj.z * oy, -1.0);
    rd = nd * inv;
}

#endif
