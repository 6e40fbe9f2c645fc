//! What a picture file's values say about light. Cameras and video encode light with a
//! transfer curve (sRGB's; Rec. 709's is close to it) before writing 8-bit values, so a pixel
//! that sees two surfaces half and half holds the encoding of their mean light, not the mean
//! of their encoded values: anything that reads a mix from a picture (an edge's share of each
//! side) decodes first.

/// An encoded 8-bit value as linear light (1: the brightest).
pub fn linear(v: u8) -> f32 {
    decoded(v as f64) as f32
}

/// An encoded value on the 0-255 scale as linear light; values past 255 (a highlight brighter
/// than the file can hold) continue the curve.
pub fn decoded(v: f64) -> f64 {
    let c = v.max(0.0) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light (1: the brightest) as its encoded value, 0-255 unrounded (clamped).
pub fn encoded(l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    let c = if l <= 0.0031308 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    255.0 * c
}

/// Every 8-bit value's linear light.
pub fn linear_table() -> [f32; 256] {
    std::array::from_fn(|v| linear(v as u8))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoding_and_decoding_are_inverse() {
        for v in 0..=255u8 {
            assert!((encoded(linear(v) as f64) - v as f64).abs() < 0.01, "{v}");
        }
        // Half the light encodes well above half the values.
        assert_eq!(encoded(0.5).round(), 188.0);
    }
}
