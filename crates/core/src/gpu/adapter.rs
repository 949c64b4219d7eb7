//! The adapters: the wgpu instance of this process, made for compute alone, and the adapter a
//! render gathers on.
//!
//! The instance enables no presentation extension where fogplanes makes it itself (Vulkan on
//! Linux and the BSDs): wgpu's own instance enables `VK_KHR_wayland_surface`,
//! `VK_KHR_xcb_surface` and `VK_KHR_xlib_surface` wherever the driver offers them, and Mesa's
//! device-selection layer (`VK_LAYER_MESA_device_select`, an implicit layer installed with
//! Mesa's Vulkan drivers, lavapipe's among them) then connects to the Wayland compositor to
//! find the default GPU: without a desktop session, libwayland-client prints
//! `error: XDG_RUNTIME_DIR is invalid or not set in the environment.` on stderr, once per
//! enumeration of the adapters. A compute-only render presents nothing, so it asks for no
//! surface, and the layer has nothing to look up.

use super::device::{Gpu, block_on, kind_name};
use super::{AdapterInfo, GPU_VARIABLE, Tuning};
use std::sync::{Arc, Mutex, OnceLock};

/// The instance of this process, made once; `Err` says why there is none (no Vulkan loader
/// or driver).
pub(super) fn instance() -> Result<&'static wgpu::Instance, String> {
    static INSTANCE: OnceLock<Result<wgpu::Instance, String>> = OnceLock::new();
    INSTANCE.get_or_init(make_instance).as_ref().map_err(|e| no_adapter(e))
}

/// The platforms whose Vulkan instance fogplanes makes itself (elsewhere: Metal, DX12, or
/// Vulkan without Mesa's layer, through wgpu's own instance).
#[cfg(all(unix, not(target_vendor = "apple"), not(target_os = "android")))]
fn make_instance() -> Result<wgpu::Instance, String> {
    use std::ffi::CStr;
    use wgpu::hal;
    // The window systems' surfaces: the only instance extensions a compute-only device does
    // without that Mesa's layer reads (it connects to Wayland, or to X through xcb, when they
    // are enabled).
    const PRESENTATION: [&CStr; 3] = [c"VK_KHR_wayland_surface", c"VK_KHR_xcb_surface", c"VK_KHR_xlib_surface"];
    let desc = hal::InstanceDescriptor {
        name: "fogplanes",
        flags: wgpu::InstanceFlags::default(),
        memory_budget_thresholds: Default::default(),
        backend_options: Default::default(),
        telemetry: None,
        display: None,
    };
    let callback: Box<hal::vulkan::CreateInstanceCallback> = Box::new(|args| {
        args.extensions.retain(|e| !PRESENTATION.contains(e));
    });
    // SAFETY: `init_with_callback` asks its callback not to remove extensions, because wgpu
    // assumes that those it wanted and found are enabled. In wgpu-hal 30.0.2 (pinned exactly in
    // Cargo.toml) the three removed here are used only to create a surface from a window,
    // which checks first that its extension is in the instance's list (the list given back by
    // this callback, `InstanceShared::extensions`) and fails cleanly if not; fogplanes creates
    // no surface. Nothing else is changed: the descriptor is the one wgpu-core builds.
    match unsafe { hal::vulkan::Instance::init_with_callback(&desc, Some(callback)) } {
        // SAFETY: a valid Vulkan instance, which wgpu now owns alone.
        Ok(hal_instance) => Ok(unsafe { wgpu::Instance::from_hal::<hal::api::Vulkan>(hal_instance) }),
        Err(e) => Err(format!("Vulkan: {e}")),
    }
}

#[cfg(not(all(unix, not(target_vendor = "apple"), not(target_os = "android"))))]
fn make_instance() -> Result<wgpu::Instance, String> {
    Ok(wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::PRIMARY,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    }))
}

/// Why there is no adapter, in one line with what to do.
fn no_adapter(why: &dyn std::fmt::Display) -> String {
    format!(
        "no GPU adapter through Vulkan, Metal or DX12 ({why}): install a Vulkan driver (the GPU vendor's, or Mesa's lavapipe on the CPU: Debian's mesa-vulkan-drivers)"
    )
}

/// The adapters of this process, in the order wgpu finds them, found once.
fn found() -> Result<&'static [wgpu::Adapter], String> {
    static FOUND: OnceLock<Result<Vec<wgpu::Adapter>, String>> = OnceLock::new();
    FOUND
        .get_or_init(|| {
            let _s = crate::trace::span("adapters found");
            let all = block_on(instance()?.enumerate_adapters(wgpu::Backends::PRIMARY));
            if all.is_empty() {
                return Err(no_adapter(&"no adapter found"));
            }
            Ok(all)
        })
        .as_ref()
        .map(Vec::as_slice)
        .map_err(Clone::clone)
}

/// How much `--device gpu` prefers an adapter of this kind: a real GPU first (discrete, then
/// integrated, then virtual), an emulated one (lavapipe) last.
fn rank(kind: wgpu::DeviceType) -> u32 {
    match kind {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// The index `--device gpu` takes: the first adapter of the best rank.
fn default_index(all: &[wgpu::Adapter]) -> usize {
    (0..all.len()).min_by_key(|&i| (rank(all[i].get_info().device_type), i)).unwrap_or(0)
}

/// The index `--device gpu` takes among `all`, and how the caller named it (for an error):
/// `index` where given, else the one [`GPU_VARIABLE`] names where it is set, else
/// [`default_index`]; `Err` in one line where that names no adapter (an index out of range
/// names the count, a variable that is not an index names itself).
fn chosen_index(all: &[wgpu::Adapter], index: Option<usize>) -> Result<usize, String> {
    let set = std::env::var(GPU_VARIABLE).ok().filter(|v| !v.is_empty());
    let (index, named) = match (index, set) {
        (None, Some(v)) => {
            // Surrounding spaces are a launcher's (`FOGPLANES_GPU=" 1"`); the index itself is
            // digits alone, as in gpu:N.
            let i = super::adapter_index(v.trim()).ok_or_else(|| {
                format!("{GPU_VARIABLE}={v:?}: not an adapter's index (0, 1, ...: `fogplanes devices` lists them)")
            })?;
            (Some(i), format!("{GPU_VARIABLE}={i}"))
        }
        (index, _) => (index, format!("gpu:{}", index.unwrap_or_default())),
    };
    match index {
        None => Ok(default_index(all)),
        Some(i) if i < all.len() => Ok(i),
        Some(_) => {
            let n = all.len();
            let which = if n == 1 {
                "is 1 adapter, gpu:0".to_string()
            } else {
                format!("are {n} adapters, gpu:0 to gpu:{}", n - 1)
            };
            Err(format!("{named}: there {which} (`fogplanes devices` lists them)"))
        }
    }
}

/// The index `--device gpu` takes, no device made: `Err` says in one line why there is none
/// (no adapter, or a [`GPU_VARIABLE`] that names none).
pub fn default_adapter() -> Result<usize, String> {
    chosen_index(found()?, None)
}

/// Every adapter wgpu finds (Vulkan, Metal, DX12), with its index, the one `--device gpu`
/// takes marked (none where [`GPU_VARIABLE`] names no adapter: [`default_adapter`] says why);
/// `Err` says in one line why there is none.
pub fn adapters() -> Result<Vec<AdapterInfo>, String> {
    let all = found()?;
    let default = chosen_index(all, None).ok();
    Ok(all
        .iter()
        .enumerate()
        .map(|(index, a)| {
            let (info, limits) = (a.get_info(), a.limits());
            AdapterInfo {
                index,
                name: info.name,
                backend: format!("{:?}", info.backend),
                kind: kind_name(info.device_type),
                max_binding: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
                default: Some(index) == default,
            }
        })
        .collect())
}

/// A device made on an adapter, or why it could not be.
type Made = Result<Arc<Gpu>, String>;

/// The adapter `index` of [`adapters`] (`None`: the one `--device gpu` takes, adapter
/// [`GPU_VARIABLE`] where it is set, else a real GPU first), its device made on first use and
/// kept for the process (with the [`Tuning`] its variables give then), with its
/// index; `Err` says in one line why there is none (an index out of range names the count, a
/// variable that is not a number it takes names itself).
pub fn adapter_at(index: Option<usize>) -> Result<(usize, Arc<Gpu>), String> {
    static GPUS: Mutex<Vec<(usize, Made)>> = Mutex::new(Vec::new());
    let all = found()?;
    let tuning = Tuning::from_env()?;
    let i = chosen_index(all, index)?;
    // Held while the device is made: two threads asking for one adapter make it once.
    let mut gpus = GPUS.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, g)) = gpus.iter().find(|(k, _)| *k == i) {
        return g.clone().map(|g| (i, g));
    }
    let _s = crate::trace::span("device made");
    let made = Gpu::new(all[i].clone(), tuning).map(Arc::new);
    gpus.push((i, made.clone()));
    made.map(|g| (i, g))
}

/// The adapter `--device gpu` takes ([`adapter_at`] of `None`).
pub fn adapter() -> Result<Arc<Gpu>, String> {
    adapter_at(None).map(|(_, g)| g)
}
