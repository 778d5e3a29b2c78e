// Particle boundary conditions (impulses, velocity overrides), in order, per particle.
// Mirrors `r4d_mpm::transfer::particle_bcs`.
#import lib/transfer.wgsl

@group(0) @binding(0) var<uniform> c: StepConsts;
@group(0) @binding(1) var<uniform> counts: Counts;
@group(0) @binding(2) var<storage, read> bcs: array<ParticleBc>;
@group(0) @binding(3) var<storage, read> x0: array<f32>;
@group(0) @binding(4) var<storage, read> mass: array<f32>;
@group(0) @binding(5) var<storage, read_write> v: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg, 64u);
    if i >= counts.particles {
        return;
    }
    let p0 = vec3<f32>(x0[3u * i], x0[3u * i + 1u], x0[3u * i + 2u]);
    var vel = vec3<f32>(v[3u * i], v[3u * i + 1u], v[3u * i + 2u]);
    for (var b = 0u; b < c.n_particle_bcs; b++) {
        let bc = bcs[b];
        let d = abs(p0 - bc.point);
        if !(window_active(bc.start, bc.end, c.time) && d.x < bc.size.x && d.y < bc.size.y && d.z < bc.size.z) {
            continue;
        }
        if bc.kind == PBC_IMPULSE {
            vel = vel + bc.vector / mass[i] * c.dt;
        } else if bc.kind == PBC_VELOCITY {
            vel = bc.vector;
        }
    }
    v[3u * i] = vel.x;
    v[3u * i + 1u] = vel.y;
    v[3u * i + 2u] = vel.z;
}
