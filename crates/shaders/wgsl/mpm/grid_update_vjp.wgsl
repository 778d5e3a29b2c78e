// Reverse of the grid node update, one thread per node: from the adjoint of the node's final
// velocity (`grid_bar`, scattered by g2p_vjp) to the adjoint of its scattered [momentum, mass]
// (`grid_in_bar`), through damping, gravity and every boundary condition (piecewise: the
// branch the forward pass took). Mirrors `grid_node_update_vjp` and `apply_grid_bcs_vjp` of
// `r4d_mpm::adjoint::transfer_vjp`.
#import lib/transfer.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> bcs: array<GridBc>;
@group(0) @binding(3) var<storage, read> grid_in: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> grid_bar: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> grid_in_bar: array<vec4<f32>>;

fn bcs_vjp(ijk: vec3<u32>, v_in: vec3<f32>, v_bar: vec3<f32>) -> vec3<f32> {
    let n = c.n_grid;
    var bar = v_bar;
    for (var ii = c.n_grid_bcs; ii > 0u; ii--) {
        let i = ii - 1u;
        // The velocity before condition i: replay the ones before it.
        var vb = v_in;
        for (var b = 0u; b < i; b++) {
            vb = apply_grid_bc(ijk, vb, bcs[b], c);
        }
        let bc = bcs[i];
        let on = window_active(bc.start, bc.end, c.time);
        if bc.kind == BC_BOUNDING_BOX {
            if on {
                let l = bc.layers;
                if bc.mode == 0u {
                    if ijk.x < l || ijk.x + l >= n || ijk.y < l || ijk.y + l >= n || ijk.z < l || ijk.z + l >= n {
                        bar = vec3<f32>(0.0);
                    }
                } else {
                    for (var a = 0u; a < 3u; a++) {
                        if (ijk[a] < l && vb[a] < 0.0) || (ijk[a] + l >= n && vb[a] > 0.0) {
                            bar[a] = 0.0;
                        }
                    }
                }
            }
        } else if bc.kind == BC_CUBOID {
            let pos = node_pos(ijk, c);
            let shift = c.time - bc.start;
            var inside = on;
            for (var a = 0u; a < 3u; a++) {
                inside = inside && abs(pos[a] - (bc.point[a] + bc.velocity[a] * shift)) < bc.axis[a];
            }
            let resets = !on && bc.layers == 1u && c.time < bc.end + 15.0 * c.dt;
            if inside || resets {
                bar = vec3<f32>(0.0);
            }
        } else if bc.kind == BC_SURFACE {
            let pos = node_pos(ijk, c);
            let d = (pos.x - bc.point.x) * bc.axis.x + (pos.y - bc.point.y) * bc.axis.y + (pos.z - bc.point.z) * bc.axis.z;
            if on && d < 0.0 {
                let nrm = bc.axis;
                let vn = dot(vb, nrm);
                if bc.mode == 0u {
                    bar = vec3<f32>(0.0);
                } else if bc.mode == 1u {
                    bar = bar - dot(bar, nrm) * nrm;
                } else if vn < 0.0 {
                    let w = vb - vn * nrm;
                    let vt = sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
                    let mu = bc.friction;
                    var w_bar = bar;
                    var vn_bar = 0.0;
                    if vt > 1e-20 {
                        if vt + vn * mu > 0.0 {
                            let f = (vt + vn * mu) / vt;
                            let wb = dot(w, bar);
                            let df_dvt = -vn * mu / (vt * vt);
                            w_bar = f * bar + wb * df_dvt * w / vt;
                            vn_bar = wb * mu / vt;
                        } else {
                            w_bar = vec3<f32>(0.0);
                        }
                    }
                    bar = w_bar + nrm * (vn_bar - dot(nrm, w_bar));
                }
            }
        }
    }
    return bar;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = linear_id(gid, nwg, 64u);
    let n = counts.n_grid;
    if idx >= n * n * n {
        return;
    }
    let vb = grid_bar[idx].xyz;
    let node = grid_in[idx];
    let m = node.w;
    if (vb.x == 0.0 && vb.y == 0.0 && vb.z == 0.0) || m <= 1e-15 {
        grid_in_bar[idx] = vec4<f32>(0.0);
        return;
    }
    let ijk = vec3<u32>(idx / (n * n), (idx / n) % n, idx % n);
    let inv = 1.0 / m;
    let u = node.xyz * inv;
    var v = u + c.dt * c.gravity;
    let damp = c.grid_v_damping < 1.0;
    if damp {
        v = v * c.grid_v_damping;
    }
    var bar = bcs_vjp(ijk, v, vb);
    if damp {
        bar = bar * c.grid_v_damping;
    }
    grid_in_bar[idx] = vec4<f32>(bar * inv, -dot(bar, u) * inv);
}
