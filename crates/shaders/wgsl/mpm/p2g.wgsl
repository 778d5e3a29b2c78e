// The scatter of P2G: mass, APIC momentum (RPIC-damped C) and stress force of each particle
// to its 27-node stencil, with float atomics. Mirrors `r4d_mpm::transfer::scatter`.
#import lib/transfer.wgsl
#import atomic

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> x: array<f32>;
@group(0) @binding(3) var<storage, read> v: array<f32>;
@group(0) @binding(4) var<storage, read> cm: array<f32>;
@group(0) @binding(5) var<storage, read> mass: array<f32>;
@group(0) @binding(6) var<storage, read> stress: array<f32>;
@group(0) @binding(7) var<storage, read_write> grid_atomic: array<AtomicF32>;

fn load9(buf: u32, b: u32) -> mat3x3<f32> {
    var r: array<f32, 9>;
    for (var e = 0u; e < 9u; e++) {
        if buf == 0u {
            r[e] = cm[b + e];
        } else {
            r[e] = stress[b + e];
        }
    }
    return mat3_from_rows(r);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let n = counts.n_grid;
    let xp = vec3<f32>(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]);
    if !in_domain(xp, c.inv_dx, n) {
        return; // reported by g2p's health check
    }
    let st = stencil(xp, c.inv_dx);
    let m = mass[i];
    let vel = vec3<f32>(v[3u * i], v[3u * i + 1u], v[3u * i + 2u]);
    let s = load9(1u, 9u * i);
    var mc = damped_affine(load9(0u, 9u * i), c.rpic_damping) * m;
    let mls = c.force_form == FORCE_MLS;
    if mls {
        mc = mc + s;
    }
    let mv = m * vel;
    for (var a = 0u; a < 3u; a++) {
        for (var b = 0u; b < 3u; b++) {
            for (var o = 0u; o < 3u; o++) {
                let off = vec3<f32>(f32(a), f32(b), f32(o));
                let w = st.w[0][a] * st.w[1][b] * st.w[2][o];
                let dpos = (off - st.fx) * c.dx;
                var mom = w * (mv + mc * dpos);
                if !mls {
                    let gw = vec3<f32>(st.dw[0][a] * st.w[1][b] * st.w[2][o], st.w[0][a] * st.dw[1][b] * st.w[2][o], st.w[0][a] * st.w[1][b] * st.dw[2][o]);
                    mom = mom + s * gw;
                }
                let node = (u32(st.base.x + i32(a)) * n + u32(st.base.y + i32(b))) * n + u32(st.base.z + i32(o));
                grid_add(4u * node, mom.x);
                grid_add(4u * node + 1u, mom.y);
                grid_add(4u * node + 2u, mom.z);
                grid_add(4u * node + 3u, w * m);
            }
        }
    }
}
