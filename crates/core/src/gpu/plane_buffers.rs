//! A structure's planes as they cross to the GPU ([`PlaneData`]: their records, occluders and
//! screen polygons) and there ([`PlaneBuffers`]), uploaded as one or as a join's parts one
//! after another.

use super::device::{Gpu, Patch};
use super::polygons::{PolygonBuffers, Polygons};
use crate::error::Result;
use crate::gather::PlaneRecord;

/// A structure's planes as they cross: [`PlaneRecord`]s, the occluders, and their screen
/// polygons.
pub(super) struct PlaneData {
    pub(super) planes: Vec<PlaneRecord>,
    pub(super) occluders: Vec<crate::occlusion::Occluder>,
    pub(super) polygons: Polygons,
}

/// [`PlaneData`] on the GPU.
pub(super) struct PlaneBuffers {
    pub(super) planes: wgpu::Buffer,
    pub(super) occluders: wgpu::Buffer,
    pub(super) polygons: PolygonBuffers,
}

impl PlaneBuffers {
    /// `parts` uploaded one after another for a `width x height` image, each part's indices
    /// made the whole's as they cross (its planes' occluders; its polygons' rows and vertices,
    /// [`PolygonBuffers::upload`]), the parts themselves untouched.
    pub(super) fn upload(gpu: &Gpu, parts: &[&PlaneData], width: u32, height: u32) -> Result<Self> {
        let usage = wgpu::BufferUsages::STORAGE;
        // Where each part's occluders begin in the whole's.
        let bases: Vec<u32> = parts
            .iter()
            .scan(0u32, |at, d| {
                let base = *at;
                *at += d.occluders.len() as u32;
                Some(base)
            })
            .collect();
        let shift = |i: usize, r: &mut PlaneRecord| {
            (r.occluders_start, r.occluders_end) = (r.occluders_start + bases[i], r.occluders_end + bases[i]);
        };
        let shifted = bases.iter().any(|&b| b > 0);
        let planes = parts.iter().map(|d| d.planes.as_slice());
        Ok(PlaneBuffers {
            planes: gpu.upload_parts("planes", planes, shifted.then_some(&shift as Patch<PlaneRecord>), usage)?,
            occluders: gpu.upload_parts("occluders", parts.iter().map(|d| d.occluders.as_slice()), None, usage)?,
            polygons: PolygonBuffers::upload(gpu, parts.iter().map(|d| &d.polygons), width, height)?,
        })
    }

    /// The bytes that crossed for them.
    pub(super) fn bytes_up(&self) -> u64 {
        self.planes.size() + self.occluders.size() + self.polygons.bytes_up()
    }
}
