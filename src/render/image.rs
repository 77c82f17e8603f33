//! The rendered picture: linear RGB floats, written as 8-bit sRGB PNG or linear float OpenEXR.

use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

/// A linear-RGB image, row by row from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB radiance, row by row from the top.
    pub pixels: Vec<Vec3>,
}

/// Linear to sRGB-encoded (IEC 61966-2-1), clamped to [0, 1]; NaN becomes 0.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, pixels: vec![Vec3::ZERO; width as usize * height as usize] }
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// 8-bit sRGB bytes, RGB interleaved.
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.pixels.iter().flat_map(|p| p.to_array().map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)).collect()
    }

    /// Writes the image: `.exr` as linear 32-bit float RGB, anything else as 8-bit sRGB PNG. The
    /// file appears whole or not at all: written beside the target under a temporary name, then
    /// renamed over it.
    pub fn write(&self, path: &Path) -> Result<()> {
        let err = |message: String| Error::ImageWrite { path: path.to_path_buf(), message };
        let exr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let name = path.file_name().ok_or_else(|| err("the path names no file".into()))?;
        let tmp = path.with_file_name(format!(".{}.{}.partial", name.to_string_lossy(), std::process::id()));
        let result = if exr {
            let data: Vec<f32> = self.pixels.iter().flat_map(|p| p.to_array()).collect();
            image::Rgb32FImage::from_raw(self.width, self.height, data)
                .ok_or_else(|| err("pixel count does not match the size".into()))
                .and_then(|img| img.save_with_format(&tmp, image::ImageFormat::OpenExr).map_err(|e| err(e.to_string())))
        } else {
            image::RgbImage::from_raw(self.width, self.height, self.to_srgb8())
                .ok_or_else(|| err("pixel count does not match the size".into()))
                .and_then(|img| img.save_with_format(&tmp, image::ImageFormat::Png).map_err(|e| err(e.to_string())))
        };
        match result.and_then(|()| std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))) {
            Ok(()) => Ok(()),
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                Err(e)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curve() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        assert!((linear_to_srgb(0.214_041_14) - 0.5).abs() < 1e-4);
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
        assert_eq!(linear_to_srgb(7.0), linear_to_srgb(1.0));
    }

    #[test]
    fn png_and_exr_round_trip_and_failures_leave_nothing() {
        let dir = std::env::temp_dir().join(format!("strahl-image-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(3, 2);
        img.pixels[4] = Vec3::new(1.0, 0.5, 0.0);
        img.write(&dir.join("a.png")).unwrap();
        let back = image::open(dir.join("a.png")).unwrap().to_rgb8();
        assert_eq!(back.get_pixel(1, 1).0, [255, 188, 0]);
        img.write(&dir.join("a.exr")).unwrap();
        let back = image::open(dir.join("a.exr")).unwrap().to_rgb32f();
        assert_eq!(back.get_pixel(1, 1).0, [1.0, 0.5, 0.0]);
        // A directory that does not exist: an error, and no file left behind.
        let e = img.write(&dir.join("missing/b.png")).unwrap_err();
        assert!(e.to_string().contains("b.png"), "{e}");
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 2, "{left:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
