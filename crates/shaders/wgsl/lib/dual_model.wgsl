// Forward-mode dual numbers (10 directions: 3 singular values, 2 plastic state entries, mu,
// lambda, plastic viscosity, Drucker-Prager alpha, hardening coefficient) and the scalar part of every isotropic model
// on them: a WGSL mirror of `Dual` in crates/mpm/src/adjoint/constitutive_vjp.rs and of
// `scalar_model` in crates/mpm/src/constitutive.rs (same formulas and branch order; f32 here,
// f64 on the CPU).
#import lib/structs.wgsl

const DIRS: u32 = 10u;

struct Dual {
    v: f32,
    d: array<f32, 10>,
}

fn dcst(x: f32) -> Dual {
    var r: Dual;
    r.v = x;
    return r;
}

fn dvar(x: f32, i: u32) -> Dual {
    var r: Dual;
    r.v = x;
    r.d[i] = 1.0;
    return r;
}

fn dadd(a: Dual, b: Dual) -> Dual {
    var r: Dual;
    r.v = a.v + b.v;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = a.d[e] + b.d[e];
    }
    return r;
}

fn dsub(a: Dual, b: Dual) -> Dual {
    var r: Dual;
    r.v = a.v - b.v;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = a.d[e] - b.d[e];
    }
    return r;
}

fn dmul(a: Dual, b: Dual) -> Dual {
    var r: Dual;
    r.v = a.v * b.v;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = a.d[e] * b.v + a.v * b.d[e];
    }
    return r;
}

fn ddiv(a: Dual, b: Dual) -> Dual {
    let inv = 1.0 / b.v;
    let q = a.v * inv;
    var r: Dual;
    r.v = q;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = (a.d[e] - q * b.d[e]) * inv;
    }
    return r;
}

fn dneg(a: Dual) -> Dual {
    var r: Dual;
    r.v = -a.v;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = -a.d[e];
    }
    return r;
}

// The derivative vector scaled by k, with value v.
fn dchain(a: Dual, v: f32, k: f32) -> Dual {
    var r: Dual;
    r.v = v;
    for (var e = 0u; e < DIRS; e++) {
        r.d[e] = a.d[e] * k;
    }
    return r;
}

fn dln(a: Dual) -> Dual {
    return dchain(a, log(a.v), 1.0 / a.v);
}

fn dexp(a: Dual) -> Dual {
    let e = exp(a.v);
    return dchain(a, e, e);
}

fn dsqrt(a: Dual) -> Dual {
    let r = sqrt(a.v);
    // At 0 (the norm of a zero vector) the derivative does not exist; use 0.
    return dchain(a, r, select(0.0, 0.5 / r, r > 0.0));
}

fn dabs(a: Dual) -> Dual {
    if a.v < 0.0 {
        return dneg(a);
    }
    return a;
}

fn dmax(a: Dual, o: Dual) -> Dual {
    if o.v > a.v {
        return o;
    }
    return a;
}

fn dmin(a: Dual, o: Dual) -> Dual {
    if o.v < a.v {
        return o;
    }
    return a;
}

fn dnorm3(v: array<Dual, 3>) -> Dual {
    return dsqrt(dadd(dadd(dmul(v[0], v[0]), dmul(v[1], v[1])), dmul(v[2], v[2])));
}

struct DualOut {
    sigma_e: array<Dual, 3>,
    t: array<Dual, 3>,
    state: array<Dual, 2>,
    unchanged: bool,
}

// t_i = 2 mu (s_i - 1) s_i + lambda J (J - 1).
fn dfixed_corotated(s: array<Dual, 3>, mu: Dual, lambda: Dual) -> array<Dual, 3> {
    let two = dcst(2.0);
    let one = dcst(1.0);
    let j = dmul(dmul(s[0], s[1]), s[2]);
    let vol = dmul(dmul(lambda, j), dsub(j, one));
    var t: array<Dual, 3>;
    for (var i = 0u; i < 3u; i++) {
        t[i] = dadd(dmul(dmul(dmul(two, mu), dsub(s[i], one)), s[i]), vol);
    }
    return t;
}

// t_i = (2 mu log s_i + lambda sum log s_j) s_i with the logs of max(s, 0.01).
fn dstvk_hencky(s: array<Dual, 3>, mu: Dual, lambda: Dual) -> array<Dual, 3> {
    let two = dcst(2.0);
    var l: array<Dual, 3>;
    for (var i = 0u; i < 3u; i++) {
        l[i] = dln(dmax(s[i], dcst(0.01)));
    }
    let tr = dadd(dadd(l[0], l[1]), l[2]);
    var t: array<Dual, 3>;
    for (var i = 0u; i < 3u; i++) {
        t[i] = dmul(dadd(dmul(dmul(two, mu), l[i]), dmul(lambda, tr)), s[i]);
    }
    return t;
}

// Sand's stress: 2 mu log|s| + lambda tr log|s| with the logs of max(|s|, 1e-14).
fn ddp_stress(s: array<Dual, 3>, mu: Dual, lambda: Dual) -> array<Dual, 3> {
    let two = dcst(2.0);
    var l: array<Dual, 3>;
    for (var i = 0u; i < 3u; i++) {
        l[i] = dln(dmax(dabs(s[i]), dcst(1e-14)));
    }
    let tr = dadd(dadd(l[0], l[1]), l[2]);
    var t: array<Dual, 3>;
    for (var i = 0u; i < 3u; i++) {
        t[i] = dadd(dmul(dmul(two, mu), l[i]), dmul(lambda, tr));
    }
    return t;
}

fn dkeep(sigma: array<Dual, 3>, t: array<Dual, 3>, state: array<Dual, 2>) -> DualOut {
    return DualOut(sigma, t, state, true);
}

fn dzero3() -> array<Dual, 3> {
    return array<Dual, 3>(dcst(0.0), dcst(0.0), dcst(0.0));
}

// `scalar_model` on duals: sigma (3), state (2) and the constants are the inputs.
fn dual_scalar_model(pc: PartConsts, sigma: array<Dual, 3>, state: array<Dual, 2>, mu: Dual, lambda: Dual, eta: Dual, alpha: Dual, h: Dual, dt: f32) -> DualOut {
    let two = dcst(2.0);
    let three = dcst(3.0);
    let one = dcst(1.0);
    switch pc.material {
        case 0u: {
            return dkeep(sigma, dfixed_corotated(sigma, mu, lambda), state);
        }
        case 1u, 5u: {
            let plasticine = pc.material == MAT_PLASTICINE;
            let y = state[0];
            if plasticine && y.v <= 0.0 {
                return dkeep(sigma, dzero3(), state);
            }
            var eps: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                eps[i] = dln(dmax(sigma[i], dcst(0.01)));
            }
            let tr = dadd(dadd(eps[0], eps[1]), eps[2]);
            var t: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                t[i] = dadd(dmul(dmul(two, mu), eps[i]), dmul(lambda, tr));
            }
            let mt = ddiv(dadd(dadd(t[0], t[1]), t[2]), three);
            var d: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                d[i] = dsub(t[i], mt);
            }
            if dnorm3(d).v > y.v {
                let third = ddiv(tr, three);
                var eps_hat: array<Dual, 3>;
                for (var i = 0u; i < 3u; i++) {
                    eps_hat[i] = dsub(eps[i], third);
                }
                let nh = dnorm3(eps_hat);
                let n = dadd(nh, dcst(1e-6));
                let dgamma = dsub(n, ddiv(y, dmul(two, mu)));
                let kk = ddiv(dgamma, n);
                var sigma_e: array<Dual, 3>;
                for (var i = 0u; i < 3u; i++) {
                    sigma_e[i] = dexp(dsub(eps[i], dmul(kk, eps_hat[i])));
                }
                var st = state;
                var stress: array<Dual, 3>;
                if plasticine {
                    stress = dfixed_corotated(sigma_e, mu, lambda);
                    st[0] = dsub(y, dmul(dmul(h, nh), dabs(kk)));
                    if st[0].v <= 0.0 {
                        stress = dzero3();
                    }
                } else {
                    stress = dstvk_hencky(sigma_e, mu, lambda);
                    // y exactly without hardening (h = 0), with its derivative in h.
                    st[0] = dadd(y, dmul(dmul(dmul(two, mu), h), dgamma));
                }
                return DualOut(sigma_e, stress, st, false);
            } else if plasticine {
                return dkeep(sigma, dfixed_corotated(sigma, mu, lambda), state);
            }
            return dkeep(sigma, dstvk_hencky(sigma, mu, lambda), state);
        }
        case 2u: {
            var eps: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                eps[i] = dln(dmax(dabs(sigma[i]), dcst(1e-14)));
            }
            let tr = dadd(dadd(eps[0], eps[1]), eps[2]);
            let third = ddiv(tr, three);
            var eps_hat: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                eps_hat[i] = dsub(eps[i], third);
            }
            let n = dnorm3(eps_hat);
            let dgamma = dadd(n, dmul(dmul(ddiv(dadd(dmul(three, lambda), dmul(two, mu)), dmul(two, mu)), tr), alpha));
            if dgamma.v <= 0.0 {
                return dkeep(sigma, ddp_stress(sigma, mu, lambda), state);
            }
            var sigma_e: array<Dual, 3>;
            if tr.v > 0.0 {
                sigma_e = array<Dual, 3>(one, one, one);
            } else {
                let kk = ddiv(dgamma, n);
                for (var i = 0u; i < 3u; i++) {
                    sigma_e[i] = dexp(dsub(eps[i], dmul(kk, eps_hat[i])));
                }
            }
            return DualOut(sigma_e, ddp_stress(sigma_e, mu, lambda), state, false);
        }
        case 3u, 7u: {
            let paste = pc.material == 7u;
            var c: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                c[i] = dmax(sigma[i], dcst(0.01));
            }
            let equal = paste && c[0].v == c[1].v && c[1].v == c[2].v;
            let w = array<f32, 3>(bitcast<f32>(0x3F7FFFFBu), bitcast<f32>(0x3F7FFFFCu), bitcast<f32>(0x3F7FFFFFu));
            let lw = array<f32, 3>(-2.9802326828588295e-07, -2.3841860752327643e-07, -5.960464655174753e-08);
            var s: array<Dual, 3>;
            var eps: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                if equal {
                    s[i] = dmul(c[i], dcst(w[i]));
                    eps[i] = dadd(dln(c[i]), dcst(lw[i]));
                } else {
                    s[i] = c[i];
                    eps[i] = dln(c[i]);
                }
            }
            let b_tr = ddiv(dadd(dadd(dmul(s[0], s[0]), dmul(s[1], s[1])), dmul(s[2], s[2])), three);
            let tr = dadd(dadd(eps[0], eps[1]), eps[2]);
            let third = ddiv(tr, three);
            var s_trial: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                s_trial[i] = dmul(dmul(two, mu), dsub(eps[i], third));
            }
            let s_norm = dnorm3(s_trial);
            let y = dsub(s_norm, dmul(dcst(0.816496580927726), state[0]));
            if paste || y.v > 0.0 {
                let mu_hat = dmul(mu, b_tr);
                let s_new_norm = dsub(s_norm, ddiv(y, dadd(one, ddiv(eta, dmul(dmul(two, mu_hat), dcst(dt))))));
                let kk = ddiv(s_new_norm, s_norm);
                var sigma_e: array<Dual, 3>;
                for (var i = 0u; i < 3u; i++) {
                    sigma_e[i] = dexp(dadd(ddiv(dmul(kk, s_trial[i]), dmul(two, mu)), third));
                }
                return DualOut(sigma_e, dstvk_hencky(sigma_e, mu, lambda), state, false);
            }
            return dkeep(sigma, dstvk_hencky(sigma, mu, lambda), state);
        }
        case 8u: {
            let j = dmul(dmul(sigma[0], sigma[1]), sigma[2]);
            let bj = dmax(dmul(j, j), dcst(1e-8));
            let f = dexp(dmul(dln(bj), dcst(-1.0 / 3.0)));
            var b: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                b[i] = dmul(dmul(f, sigma[i]), sigma[i]);
            }
            let mb = ddiv(dadd(dadd(b[0], b[1]), b[2]), three);
            let p = dmul(dadd(ddiv(lambda, two), ddiv(mu, three)), dadd(dsub(dmul(j, j), one), dcst(1e-8)));
            var t: array<Dual, 3>;
            for (var i = 0u; i < 3u; i++) {
                t[i] = dadd(p, dmul(mu, dsub(b[i], mb)));
            }
            return dkeep(sigma, t, state);
        }
        case 4u: {
            let lo = dcst(1.0 - pc.theta_c);
            let hi = dcst(1.0 + pc.theta_s);
            var sigma_e: array<Dual, 3>;
            var clamped = false;
            for (var i = 0u; i < 3u; i++) {
                sigma_e[i] = dmin(dmax(sigma[i], lo), hi);
                clamped = clamped || sigma_e[i].v != sigma[i].v;
            }
            let j_trial = dmul(dmul(sigma[0], sigma[1]), sigma[2]);
            let j_e = dmul(dmul(sigma_e[0], sigma_e[1]), sigma_e[2]);
            let jp = ddiv(dmul(state[1], j_trial), j_e);
            let h = dexp(dmul(dcst(pc.snow_xi), dsub(one, jp)));
            let st = array<Dual, 2>(state[0], jp);
            return DualOut(sigma_e, dfixed_corotated(sigma_e, dmul(mu, h), dmul(lambda, h)), st, !clamped);
        }
        default: {
            return dkeep(sigma, dzero3(), state);
        }
    }
}
