// Per-particle / per-node functions of a substep: WGSL mirror of `r4d_mpm::transfer`.
#import lib/structs.wgsl
#import lib/math.wgsl

struct Stencil {
    base: vec3<i32>,
    fx: vec3<f32>,
    // w[a] = weights of nodes base + 0..3 along axis a; dw their derivatives (units 1/dx).
    w: array<vec3<f32>, 3>,
    dw: array<vec3<f32>, 3>,
}

fn stencil(x: vec3<f32>, inv_dx: f32) -> Stencil {
    var s: Stencil;
    for (var a = 0u; a < 3u; a++) {
        let g = x[a] * inv_dx;
        let b = i32(g - 0.5);
        let f = g - f32(b);
        s.base[a] = b;
        s.fx[a] = f;
        s.w[a] = vec3<f32>(0.5 * (1.5 - f) * (1.5 - f), 0.75 - (f - 1.0) * (f - 1.0), 0.5 * (f - 0.5) * (f - 0.5));
        s.dw[a] = vec3<f32>(f - 1.5, -2.0 * (f - 1.0), f - 0.5);
    }
    return s;
}

fn in_domain(x: vec3<f32>, inv_dx: f32, n: u32) -> bool {
    let hi = f32(n) - 1.5;
    for (var a = 0u; a < 3u; a++) {
        let g = x[a] * inv_dx;
        if !(is_finite_f32(g) && g >= 0.5 && g < hi) {
            return false;
        }
    }
    return true;
}

fn window_active(start: f32, end: f32, t: f32) -> bool {
    return start <= t && t < end;
}

fn stress_scale(vol0: f32, c: StepConsts) -> f32 {
    if c.force_form == FORCE_MLS {
        return -c.dt * vol0 * 4.0 * c.inv_dx * c.inv_dx;
    }
    return -c.dt * vol0 * c.inv_dx;
}

fn damped_affine(cm: mat3x3<f32>, r: f32) -> mat3x3<f32> {
    if r < -0.001 {
        return mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    }
    if r == 0.0 {
        return cm;
    }
    return cm * (1.0 - r) + (cm - transpose(cm)) * (0.5 * r);
}

fn node_pos(ijk: vec3<u32>, c: StepConsts) -> vec3<f32> {
    return vec3<f32>(f32(ijk.x) * c.dx, f32(ijk.y) * c.dx, f32(ijk.z) * c.dx);
}

fn apply_grid_bc(ijk: vec3<u32>, v_in: vec3<f32>, bc: GridBc, c: StepConsts) -> vec3<f32> {
    var v = v_in;
    let n = c.n_grid;
    if bc.kind == BC_BOUNDING_BOX {
        if !window_active(bc.start, bc.end, c.time) {
            return v;
        }
        let l = bc.layers;
        if bc.mode == 0u {
            for (var a = 0u; a < 3u; a++) {
                if ijk[a] < l || ijk[a] + l >= n {
                    return vec3<f32>(0.0);
                }
            }
        } else {
            for (var a = 0u; a < 3u; a++) {
                if (ijk[a] < l && v[a] < 0.0) || (ijk[a] + l >= n && v[a] > 0.0) {
                    v[a] = 0.0;
                }
            }
        }
    } else if bc.kind == BC_CUBOID {
        let pos = node_pos(ijk, c);
        let shift = c.time - bc.start;
        var inside = window_active(bc.start, bc.end, c.time);
        for (var a = 0u; a < 3u; a++) {
            inside = inside && abs(pos[a] - (bc.point[a] + bc.velocity[a] * shift)) < bc.axis[a];
        }
        if inside {
            v = bc.velocity;
        } else if !window_active(bc.start, bc.end, c.time) && bc.layers == 1u && c.time < bc.end + 15.0 * c.dt {
            v = vec3<f32>(0.0);
        }
    } else if bc.kind == BC_SURFACE {
        let pos = node_pos(ijk, c);
        let d = (pos.x - bc.point.x) * bc.axis.x + (pos.y - bc.point.y) * bc.axis.y + (pos.z - bc.point.z) * bc.axis.z;
        if window_active(bc.start, bc.end, c.time) && d < 0.0 {
            let nrm = bc.axis;
            let vn = v.x * nrm.x + v.y * nrm.y + v.z * nrm.z;
            if bc.mode == 0u {
                v = vec3<f32>(0.0);
            } else if bc.mode == 1u {
                v = v - vn * nrm;
            } else if vn < 0.0 {
                v = v - vn * nrm;
                let vt = sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
                if vt > 1e-20 {
                    v = v * (max(vt + vn * bc.friction, 0.0) / vt);
                }
            }
        }
    }
    return v;
}
