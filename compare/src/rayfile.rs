//! The ray and hit file formats of BENCHMARKING.md, so that any program can trace the same rays.
//!
//! - rays: bytes `RAYS`, u32 count, then count × 8 little-endian f32: ox oy oz tnear dx dy dz tfar
//! - hits: count × (f32 t, or +inf for a miss; u32 primitive id, or 0xffffffff for a miss)
//!
//! Primitive ids in hit files are scene-global: the triangle's index plus the triangle counts of
//! all earlier geometries.

use std::io::{Read, Write};
use std::path::Path;

use anyhow::{Context, bail};
use strahl::{INVALID_ID, RayStream, TriangleMesh};

use crate::harness::Answers;

pub fn write_rays(path: &Path, rays: &RayStream) -> anyhow::Result<()> {
    let mut buf = Vec::with_capacity(8 + rays.len() * 32);
    buf.extend_from_slice(b"RAYS");
    buf.extend_from_slice(&(rays.len() as u32).to_le_bytes());
    for i in 0..rays.len() {
        for x in [rays.ox[i], rays.oy[i], rays.oz[i], rays.tnear[i], rays.dx[i], rays.dy[i], rays.dz[i], rays.tfar[i]] {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(&buf))
        .with_context(|| format!("writing {}", path.display()))
}

pub fn read_rays(path: &Path) -> anyhow::Result<RayStream> {
    let mut buf = Vec::new();
    std::fs::File::open(path)
        .and_then(|mut f| f.read_to_end(&mut buf))
        .with_context(|| format!("reading {}", path.display()))?;
    if buf.len() < 8 || &buf[..4] != b"RAYS" {
        bail!("{} is not a ray file (no RAYS header)", path.display());
    }
    let n = u32::from_le_bytes(buf[4..8].try_into().expect("4 bytes")) as usize;
    let need = n.checked_mul(32).and_then(|b| b.checked_add(8));
    if need != Some(buf.len()) {
        bail!("{}: header says {n} rays, but the file has {} bytes", path.display(), buf.len());
    }
    let f = |k: usize| f32::from_le_bytes(buf[k..k + 4].try_into().expect("4 bytes"));
    let mut rays = RayStream::with_capacity(n);
    for i in 0..n {
        let b = 8 + 32 * i;
        rays.ox.push(f(b));
        rays.oy.push(f(b + 4));
        rays.oz.push(f(b + 8));
        rays.tnear.push(f(b + 12));
        rays.dx.push(f(b + 16));
        rays.dy.push(f(b + 20));
        rays.dz.push(f(b + 24));
        rays.tfar.push(f(b + 28));
    }
    Ok(rays)
}

/// Global primitive id offsets of each geometry.
pub fn offsets(meshes: &[TriangleMesh]) -> Vec<u32> {
    let mut acc = 0u32;
    meshes
        .iter()
        .map(|m| {
            let o = acc;
            acc = acc.saturating_add(m.triangle_count() as u32);
            o
        })
        .collect()
}

pub fn write_hits(path: &Path, answers: &Answers, offsets: &[u32]) -> anyhow::Result<()> {
    let mut buf = Vec::with_capacity(answers.len() * 8);
    for i in 0..answers.len() {
        let (t, id) = if answers.hit(i) {
            (answers.t[i], offsets.get(answers.geom[i] as usize).copied().unwrap_or(0) + answers.prim[i])
        } else {
            (f32::INFINITY, INVALID_ID)
        };
        buf.extend_from_slice(&t.to_le_bytes());
        buf.extend_from_slice(&id.to_le_bytes());
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(&buf))
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use strahl::Ray;

    #[test]
    fn rays_round_trip_and_bad_files_are_errors() {
        let dir = std::env::temp_dir().join(format!("compare-rayfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rays: RayStream =
            (0..5).map(|i| Ray::segment(Vec3::splat(i as f32), Vec3::X, 0.5, f32::INFINITY)).collect();
        let p = dir.join("a.rays");
        write_rays(&p, &rays).unwrap();
        assert_eq!(read_rays(&p).unwrap(), rays);
        std::fs::write(dir.join("bad.rays"), b"RAYS\x05\x00\x00\x00short").unwrap();
        assert!(read_rays(&dir.join("bad.rays")).is_err());
        std::fs::write(dir.join("nohdr.rays"), b"XXXX").unwrap();
        assert!(read_rays(&dir.join("nohdr.rays")).is_err());
    }
}
