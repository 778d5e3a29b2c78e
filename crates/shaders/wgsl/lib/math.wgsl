// Small helpers shared by the kernels.

// Row-major 9 floats at `base` of a flat array -> the matrix.
fn mat3_from_rows(r: array<f32, 9>) -> mat3x3<f32> {
    return mat3x3<f32>(
        vec3<f32>(r[0], r[3], r[6]),
        vec3<f32>(r[1], r[4], r[7]),
        vec3<f32>(r[2], r[5], r[8]),
    );
}

// The matrix -> row-major 9 floats.
fn mat3_to_rows(m: mat3x3<f32>) -> array<f32, 9> {
    return array<f32, 9>(
        m[0].x, m[1].x, m[2].x,
        m[0].y, m[1].y, m[2].y,
        m[0].z, m[1].z, m[2].z,
    );
}

fn mat3_diag(d: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(vec3<f32>(d.x, 0.0, 0.0), vec3<f32>(0.0, d.y, 0.0), vec3<f32>(0.0, 0.0, d.z));
}

fn mat3_identity() -> mat3x3<f32> {
    return mat3_diag(vec3<f32>(1.0, 1.0, 1.0));
}

fn outer3(a: vec3<f32>, b: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(a * b.x, a * b.y, a * b.z);
}

fn trace3(m: mat3x3<f32>) -> f32 {
    return m[0].x + m[1].y + m[2].z;
}

fn is_finite_f32(x: f32) -> bool {
    // NaN fails every comparison; infinities exceed the largest finite float.
    return abs(x) <= 3.4028235e38;
}
