//! The Bayer mosaic: a colour image as the GC2450C's sensor delivers it raw.
//!
//! Owns [`mosaic`]: keeps, of each RGB pixel, the one channel its photosite sees in the RGGB
//! pattern (GenICam `BayerRG8`): R at (even row, even column), G at (even, odd) and
//! (odd, even), B at (odd, odd).

/// Writes the RGGB mosaic of `rgb` (width×height×3 bytes) into `out` (width×height bytes).
pub fn mosaic(rgb: &[u8], out: &mut [u8], width: usize, height: usize) {
    debug_assert_eq!(rgb.len(), width * height * 3);
    debug_assert_eq!(out.len(), width * height);
    for (r, (row_out, row_in)) in out
        .chunks_exact_mut(width)
        .zip(rgb.chunks_exact(width * 3))
        .enumerate()
        .take(height)
    {
        for (c, o) in row_out.iter_mut().enumerate() {
            let ch = match (r & 1, c & 1) {
                (0, 0) => 0,
                (1, 1) => 2,
                _ => 1,
            };
            *o = row_in[c * 3 + ch];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rggb_layout() {
        // 2x2 image, each pixel (r, g, b) distinct
        let rgb = [10, 11, 12, 20, 21, 22, 30, 31, 32, 40, 41, 42];
        let mut out = [0u8; 4];
        mosaic(&rgb, &mut out, 2, 2);
        assert_eq!(out, [10, 21, 31, 42]);
    }
}
