// G2P: gather velocity, APIC C and velocity gradient, advect, F = (I + dt grad v) F_e, and
// record the first problem of the substep (lowest particle index) in `scratch`: [0] = that
// index (atomic min), [1 + 2 i] = code, [2 + 2 i] = value bits. Mirrors
// `r4d_mpm::transfer::{gather, g2p_finish}`.
#import lib/transfer.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> nodes: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> x: array<f32>;
@group(0) @binding(4) var<storage, read_write> v: array<f32>;
@group(0) @binding(5) var<storage, read_write> cm: array<f32>;
@group(0) @binding(6) var<storage, read_write> f: array<f32>;
@group(0) @binding(7) var<storage, read_write> scratch: array<atomic<u32>>;

fn report(i: u32, code: u32, value: f32) {
    atomicStore(&scratch[1u + 2u * i], code);
    atomicStore(&scratch[2u + 2u * i], bitcast<u32>(value));
    atomicMin(&scratch[0], i);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let n = counts.n_grid;
    var xp = vec3<f32>(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]);
    if !in_domain(xp, c.inv_dx, n) {
        report(i, HEALTH_OUT_OF_DOMAIN, xp.x);
        return;
    }
    let st = stencil(xp, c.inv_dx);
    var vel = vec3<f32>(0.0);
    var cmat = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    var gv = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            for (var o = 0u; o < 3u; o++) {
                let node = (u32(st.base.x + i32(a)) * n + u32(st.base.y + i32(b))) * n + u32(st.base.z + i32(o));
                let nv = nodes[node].xyz;
                let w = st.w[0][a] * st.w[1][b] * st.w[2][o];
                let dp = vec3<f32>(f32(a), f32(b), f32(o)) - st.fx;
                let gw = vec3<f32>(st.dw[0][a] * st.w[1][b] * st.w[2][o], st.w[0][a] * st.dw[1][b] * st.w[2][o], st.w[0][a] * st.w[1][b] * st.dw[2][o]);
                vel = vel + w * nv;
                cmat = cmat + outer3(w * nv, dp);
                gv = gv + outer3(nv, gw);
            }
        }
    }
    cmat = cmat * (4.0 * c.inv_dx);
    if c.force_form == FORCE_MLS {
        gv = cmat;
    } else {
        gv = gv * c.inv_dx;
    }
    xp = xp + c.dt * vel;
    var fr: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        fr[e] = f[9u * i + e];
    }
    let fnew = (mat3_identity() + gv * c.dt) * mat3_from_rows(fr);
    let fo = mat3_to_rows(fnew);
    let co = mat3_to_rows(cmat);
    var finite = true;
    for (var e = 0u; e < 9u; e++) {
        f[9u * i + e] = fo[e];
        cm[9u * i + e] = co[e];
        finite = finite && is_finite_f32(fo[e]);
    }
    v[3u * i] = vel.x;
    v[3u * i + 1u] = vel.y;
    v[3u * i + 2u] = vel.z;
    let speed2 = dot(vel, vel);
    var code = 0u;
    var value = 0.0;
    if !(is_finite_f32(speed2) && is_finite_f32(xp.x) && is_finite_f32(xp.y) && is_finite_f32(xp.z) && finite) {
        code = HEALTH_NAN;
        value = bitcast<f32>(0x7fc00000u);
    } else if speed2 > c.max_speed * c.max_speed {
        code = HEALTH_SPEED;
        value = sqrt(speed2);
    } else if !in_domain(xp, c.inv_dx, n) {
        if c.out_of_domain == OUT_OF_DOMAIN_CLAMP {
            let lo = 0.5 * c.dx * 1.0001;
            let hi = (f32(n) - 1.5) * c.dx * 0.9999;
            xp = clamp(xp, vec3<f32>(lo), vec3<f32>(hi));
        } else {
            code = HEALTH_OUT_OF_DOMAIN;
            var worst = 0.0;
            for (var a = 0u; a < 3u; a++) {
                if abs(xp[a]) > abs(worst) {
                    worst = xp[a];
                }
            }
            value = worst;
        }
    }
    x[3u * i] = xp.x;
    x[3u * i + 1u] = xp.y;
    x[3u * i + 2u] = xp.z;
    if code != 0u {
        report(i, code, value);
    }
}
