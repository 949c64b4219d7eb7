//! Built without the `gpu` feature: no adapter, and so no planes on one.

use super::AdapterInfo;
use crate::camera::{CameraRay, RayRowFn};
use crate::control::Control;
use crate::error::Result;
use crate::gather::{GatherContext, GatherStats};
use crate::pixel::{PanelRecord, RaySetRecord};
use crate::weights::Weighting;
use glam::Vec3;
use std::sync::Arc;

/// No adapter can exist in this build.
pub enum Gpu {}

impl Gpu {
    pub fn name(&self) -> &str {
        match *self {}
    }
    pub fn is_cpu_adapter(&self) -> bool {
        match *self {}
    }
    pub fn has_timestamps(&self) -> bool {
        match *self {}
    }
    pub fn compile_gather(&self, _: Weighting) -> Result<()> {
        match *self {}
    }
    pub fn max_binding(&self) -> u64 {
        match *self {}
    }
}

const WITHOUT: &str = "this fogplanes was built without the `gpu` cargo feature: rebuild with it (on by default)";

/// Why there is no adapter.
pub fn adapter() -> std::result::Result<Arc<Gpu>, String> {
    Err(WITHOUT.into())
}

/// Why there is no adapter.
pub fn adapter_at(_: Option<usize>) -> std::result::Result<(usize, Arc<Gpu>), String> {
    Err(WITHOUT.into())
}

/// Why there is no adapter.
pub fn adapters() -> std::result::Result<Vec<AdapterInfo>, String> {
    Err(WITHOUT.into())
}

/// Why there is no adapter.
pub fn default_adapter() -> std::result::Result<usize, String> {
    Err(WITHOUT.into())
}

/// Never made: there is no [`Gpu`] to make it on.
pub enum GpuPlanes {}

impl GpuPlanes {
    pub fn new(gpu: Arc<Gpu>, _: &GatherContext, _: &[super::ScreenReach], _: u32, _: u32) -> Result<Self> {
        match *gpu {}
    }
    pub fn ray_set_bytes(&self) -> u64 {
        match *self {}
    }
    pub fn new_sums(&self) -> Result<GpuSums> {
        match *self {}
    }
    pub fn upload_rays(&self, _: &[CameraRay]) -> Result<GpuRays> {
        match *self {}
    }
    pub fn make_rays(&self, _: RayRowFn) -> Result<GpuRays> {
        match *self {}
    }
    pub fn rays_on_gpu(&self, _: &[(&RaySetRecord, &[PanelRecord])]) -> Result<GpuRays> {
        match *self {}
    }
    pub fn ray_sets_fitting(&self) -> usize {
        match *self {}
    }
    pub fn joins_pieces(&self) -> bool {
        match *self {}
    }
    pub fn join(parts: &[(&GpuPlanes, u32)]) -> Result<Option<GpuPlanes>> {
        match parts.first() {
            Some((p, _)) => match **p {},
            None => Ok(None),
        }
    }
    pub fn gather(&self, _: Weighting, _: &[CameraRay], _: &mut [Vec3], _: Control) -> Result<GatherStats> {
        match *self {}
    }
    pub fn gather_into(&self, _: Weighting, _: &GpuRays, _: &mut GpuSums, _: Control) -> Result<GatherStats> {
        match *self {}
    }
    pub fn record(&self, _: Weighting, _: &GpuRays, _: u32, _: &GpuSums, _: Control) -> Result<Recorded> {
        match *self {}
    }
}

/// Never made: there is no [`Gpu`] to make them on.
pub enum GpuRays {}

impl GpuRays {
    pub fn new(gpu: &Arc<Gpu>, _: &[CameraRay]) -> Result<Self> {
        match **gpu {}
    }
    pub fn on_gpu(gpu: &Arc<Gpu>, _: &RaySetRecord, _: &[PanelRecord]) -> Result<Self> {
        match **gpu {}
    }
    pub fn sets_on_gpu(gpu: &Arc<Gpu>, _: &[(&RaySetRecord, &[PanelRecord])]) -> Result<Self> {
        match **gpu {}
    }
    pub fn made_on_gpu(&self) -> bool {
        match *self {}
    }
    pub fn floats_at(&self, _: u32) -> u32 {
        match *self {}
    }
    pub fn wait(&self) -> Result<u64> {
        match *self {}
    }
    pub fn read(&self) -> Result<Vec<CameraRay>> {
        match *self {}
    }
    pub fn read_set(&self, _: u32) -> Result<Vec<CameraRay>> {
        match *self {}
    }
    pub fn bytes_up(&self) -> u64 {
        match *self {}
    }
    pub fn upload_ns(&self) -> u64 {
        match *self {}
    }
}

/// Never made: there is no [`Gpu`] to make them on.
pub enum GpuSums {}

/// Never made: there is no [`GpuPlanes`] to record it.
pub enum Recorded {}

impl GpuSums {
    pub fn add(&mut self, recorded: Recorded, _: &GpuRays) -> GatherStats {
        match recorded {}
    }
    pub fn submit_pending(&mut self) -> Result<()> {
        match *self {}
    }
    pub fn holds_too_many_rays(&self) -> bool {
        match *self {}
    }
    pub fn submit_held(&mut self) {
        match *self {}
    }
    pub fn read_into(&mut self, _: &mut [Vec3]) -> Result<GatherStats> {
        match *self {}
    }
    pub fn snapshot(&mut self) -> Result<()> {
        match *self {}
    }
    pub fn snapshot_bytes(&self) -> u64 {
        match *self {}
    }
    pub fn read_snapshots(&mut self, _: &mut dyn FnMut(&[[u32; 3]])) -> Result<()> {
        match *self {}
    }
}

/// A pixel's sums as the GPU holds them (f32 bits, r g b).
pub fn sums_of_bits(v: &[u32; 3]) -> Vec3 {
    Vec3::new(f32::from_bits(v[0]), f32::from_bits(v[1]), f32::from_bits(v[2]))
}
