//! H.264 byte-stream plumbing: MP4 stores NAL units with a length prefix (AVCC), the codec reads
//! and writes them with start codes (Annex B).

/// NAL unit types that matter here.
pub(crate) const NAL_IDR: u8 = 5;
pub(crate) const NAL_SPS: u8 = 7;
pub(crate) const NAL_PPS: u8 = 8;

/// Appends the NAL units of a length-prefixed sample to `out` with 4-byte start codes.
/// Returns `Err` with a message when a length runs past the sample.
pub(crate) fn avcc_to_annexb(
    sample: &[u8],
    length_size: u8,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let l = length_size as usize;
    let mut pos = 0usize;
    while pos < sample.len() {
        if sample.len() - pos < l {
            return Err(format!(
                "a NAL length prefix is cut off at byte {pos} of {}",
                sample.len()
            ));
        }
        let n = sample[pos..pos + l]
            .iter()
            .fold(0usize, |a, &b| (a << 8) | b as usize);
        pos += l;
        if n > sample.len() - pos {
            return Err(format!(
                "a NAL unit of {n} bytes at byte {pos} runs past the sample ({} bytes)",
                sample.len()
            ));
        }
        out.extend_from_slice(&[0, 0, 0, 1]);
        out.extend_from_slice(&sample[pos..pos + n]);
        pos += n;
    }
    Ok(())
}

/// The NAL units of an Annex B stream, without their start codes.
pub(crate) fn annexb_units(stream: &[u8]) -> Vec<&[u8]> {
    let mut starts = Vec::new();
    let mut i = 0usize;
    while i + 3 <= stream.len() {
        if stream[i] == 0 && stream[i + 1] == 0 && stream[i + 2] == 1 {
            starts.push((i, i + 3));
            i += 3;
        } else {
            i += 1;
        }
    }
    let mut out = Vec::with_capacity(starts.len());
    for (k, &(_, body)) in starts.iter().enumerate() {
        let mut end = starts.get(k + 1).map_or(stream.len(), |s| s.0);
        // A 4-byte start code's leading zero belongs to the next code, not to this unit.
        while end > body && stream[end - 1] == 0 && k + 1 < starts.len() {
            end -= 1;
        }
        if end > body {
            out.push(&stream[body..end]);
        }
    }
    out
}

/// The type of a NAL unit (its first byte's low five bits).
pub(crate) fn nal_type(unit: &[u8]) -> u8 {
    unit.first().map_or(0, |b| b & 0x1f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annexb_and_avcc_round_trip() {
        let stream = [
            0, 0, 0, 1, 0x67, 1, 2, 0, 0, 1, 0x68, 3, 0, 0, 0, 1, 0x65, 4, 5, 0,
        ];
        let units = annexb_units(&stream);
        assert_eq!(
            units,
            vec![&[0x67u8, 1, 2][..], &[0x68, 3][..], &[0x65, 4, 5, 0][..]]
        );
        assert_eq!(nal_type(units[2]), NAL_IDR);
        let mut avcc = Vec::new();
        for u in &units {
            avcc.extend((u.len() as u32).to_be_bytes());
            avcc.extend_from_slice(u);
        }
        let mut back = Vec::new();
        avcc_to_annexb(&avcc, 4, &mut back).unwrap();
        assert_eq!(annexb_units(&back), units);
    }

    #[test]
    fn bad_lengths_are_errors() {
        let mut out = Vec::new();
        assert!(avcc_to_annexb(&[0, 0, 0, 9, 1, 2], 4, &mut out)
            .unwrap_err()
            .contains("runs past"));
        assert!(avcc_to_annexb(&[0, 0], 4, &mut out)
            .unwrap_err()
            .contains("cut off"));
    }
}
