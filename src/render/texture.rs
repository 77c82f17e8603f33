//! Image textures (OBJ `map_Kd`): decoded once into linear RGB, sampled with bilinear filtering
//! and repeat wrapping.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};

/// Largest texture file read, in bytes.
pub const MAX_TEXTURE_BYTES: u64 = 256 << 20;

/// A texture in linear RGB, row by row from the top-left texel (image order).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageTexture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Linear RGB texels, row by row from the top.
    pub texels: Vec<Vec3>,
    /// The file it was read from (`None` for a texture made in memory): what an exporter to
    /// another renderer points at.
    pub source: Option<PathBuf>,
}

/// sRGB-encoded to linear (IEC 61966-2-1).
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

impl ImageTexture {
    /// Reads a PNG, JPEG or TGA file (a regular file up to [`MAX_TEXTURE_BYTES`]), its 8-bit
    /// sRGB colours made linear. A missing file is [`Error::Io`]; one that does not decode,
    /// [`Error::Texture`].
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = crate::geometry::obj::read_regular(path, MAX_TEXTURE_BYTES)?;
        let err = |message: String| Error::Texture { path: path.to_path_buf(), message };
        let format = image::ImageFormat::from_path(path)
            .or_else(|_| image::guess_format(&bytes))
            .map_err(|e| err(e.to_string()))?;
        let img = image::load_from_memory_with_format(&bytes, format).map_err(|e| err(e.to_string()))?.to_rgb8();
        let (width, height) = img.dimensions();
        if width == 0 || height == 0 {
            return Err(err("the image is empty".into()));
        }
        let lut: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f32 / 255.0)).collect();
        let texels =
            img.pixels().map(|p| Vec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize])).collect();
        Ok(Self { width, height, texels, source: Some(path.to_path_buf()) })
    }

    /// The colour at texture coordinates `uv` (OBJ convention: v up, (0, 0) the bottom-left
    /// corner), bilinear between the four nearest texel centres, the image repeated in both
    /// directions.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        if !uv.is_finite() {
            return self.texels[0];
        }
        let x = uv.x.rem_euclid(1.0) * w as f32 - 0.5;
        let y = (1.0 - uv.y.rem_euclid(1.0)) * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: i64, j: i64| self.texels[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
        let (i, j) = (x0 as i64, y0 as i64);
        let top = at(i, j).lerp(at(i + 1, j), fx);
        let bottom = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
        top.lerp(bottom, fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_by_two() -> ImageTexture {
        // Top row: red, green; bottom row: blue, white.
        ImageTexture { width: 2, height: 2, texels: vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE], source: None }
    }

    #[test]
    fn texel_centres_bilinear_and_repeat() {
        let t = two_by_two();
        // Texel centres: u = 0.25 / 0.75, v = 0.75 (top) / 0.25 (bottom).
        assert!((t.sample(Vec2::new(0.25, 0.75)) - Vec3::X).length() < 1e-6);
        assert!((t.sample(Vec2::new(0.75, 0.25)) - Vec3::ONE).length() < 1e-6);
        // Halfway between red and green.
        assert!((t.sample(Vec2::new(0.5, 0.75)) - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        // Repeat: shifted by whole periods, and across the seam (u = 0 is between green and red).
        assert!((t.sample(Vec2::new(3.25, -1.25)) - Vec3::X).length() < 1e-6);
        assert!((t.sample(Vec2::new(0.0, 0.75)) - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert_eq!(t.sample(Vec2::NAN), Vec3::X);
    }

    #[test]
    fn files_load_linear_and_bad_files_are_named() {
        let dir = std::env::temp_dir().join(format!("strahl-tex-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.png");
        image::RgbImage::from_raw(1, 1, vec![255, 188, 0]).unwrap().save(&p).unwrap();
        let t = ImageTexture::load(&p).unwrap();
        assert!((t.texels[0] - Vec3::new(1.0, 0.5, 0.0)).abs().max_element() < 0.01, "{}", t.texels[0]);
        std::fs::write(dir.join("bad.png"), b"not a png").unwrap();
        let e = ImageTexture::load(&dir.join("bad.png")).unwrap_err();
        assert!(matches!(e, Error::Texture { .. }) && e.to_string().contains("bad.png"), "{e}");
        assert!(matches!(ImageTexture::load(&dir.join("none.png")).unwrap_err(), Error::Io { .. }));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
