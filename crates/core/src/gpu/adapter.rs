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

use super::device::{Gpu, block_on};
use std::sync::{Arc, OnceLock};

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

/// The adapter of this process, found on first use: the high-performance one (a discrete GPU
/// before an integrated one or a CPU adapter such as lavapipe) among Vulkan, Metal and DX12.
/// `Err` says in one line why there is none.
pub fn adapter() -> Result<Arc<Gpu>, String> {
    static GPU: OnceLock<Result<Arc<Gpu>, String>> = OnceLock::new();
    GPU.get_or_init(|| {
        let adapter = block_on(instance()?.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| no_adapter(&e))?;
        Gpu::new(adapter).map(Arc::new)
    })
    .clone()
}
