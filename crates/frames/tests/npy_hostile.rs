//! Hostile `.npy` headers: sizes read from the file are checked before anything is allocated
//! or sliced (a shape whose product overflows must not wrap).

use r4d_frames::io::read_video;

/// A version-1 `.npy` with `header` (padded) and `body`.
fn npy(header: &str, body: &[u8]) -> Vec<u8> {
    let mut h = header.to_string();
    let total = 10 + h.len() + 1;
    h.push_str(&" ".repeat((64 - total % 64) % 64));
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    out.extend_from_slice(body);
    out
}

#[test]
fn overflowing_and_oversized_shapes_are_typed_errors() {
    let dir = std::env::temp_dir().join(format!("r4d_npy_hostile_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let body = vec![0u8; 4 * 2 * 2 * 2 * 3];
    let cases = [
        // t*h*w*3 wraps to 0 in 64 bits.
        "{'descr': '<f4', 'fortran_order': False, 'shape': (4611686018427387904, 4, 1, 3), }",
        // Overflows outright.
        "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551615, 2, 2, 3), }",
        // Far more values than bytes.
        "{'descr': '<f4', 'fortran_order': False, 'shape': (100000, 1000, 1000, 3), }",
        // Zero-sized.
        "{'descr': '<f4', 'fortran_order': False, 'shape': (0, 2, 2, 3), }",
    ];
    for (i, header) in cases.iter().enumerate() {
        let path = dir.join(format!("case{i}.npy"));
        std::fs::write(&path, npy(header, &body)).unwrap();
        let r = read_video::<f32>(&path);
        let e = r.expect_err(header);
        assert!(
            e.to_string().contains(&format!("case{i}.npy")),
            "the error names the file: {e}"
        );
    }
    // The well-formed file of the same body reads.
    let path = dir.join("ok.npy");
    std::fs::write(
        &path,
        npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2, 3), }",
            &body,
        ),
    )
    .unwrap();
    let v = read_video::<f32>(&path).unwrap();
    assert_eq!((v.frames(), v.height(), v.width()), (2, 2, 2));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_frame_folder_too_large_for_memory_is_refused_after_its_first_frame() {
    let dir = std::env::temp_dir().join(format!("r4d_frames_hostile_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // 1000 x 1000 px: 12 MB a frame as f32, 1000 frames are 12 GB > 8 GiB.
    let f = dir.join("frame.png");
    image::RgbImage::new(1000, 1000).save(&f).unwrap();
    let files = vec![f; 1000];
    let e = r4d_frames::io::read_frames::<f32>(&files, &dir)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("MAX_VIDEO_BYTES") && e.contains("1000 frames"),
        "{e}"
    );
    // Small frames read as before.
    let small = dir.join("small.png");
    image::RgbImage::new(4, 4).save(&small).unwrap();
    let v = r4d_frames::io::read_frames::<f32>(&vec![small; 3], &dir).unwrap();
    assert_eq!(v.frames(), 3);
    let _ = std::fs::remove_dir_all(&dir);
}
