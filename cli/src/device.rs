//! `--device auto|cpu|gpu`: which processor a command runs on.

use crate::Failure;
use gsi::gpu::Gpu;

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    Auto,
    Cpu,
    Gpu,
}

/// The GPU a command should use, if any: `cpu` never looks; `gpu` takes any adapter wgpu
/// offers, software ones included, and fails without one; `auto` takes a hardware
/// adapter and otherwise says once that it runs on the CPU (`doing` names the work),
/// unless `quiet`.
pub fn open(device: DeviceArg, doing: &str, quiet: bool) -> Result<Option<Gpu>, Failure> {
    if device == DeviceArg::Cpu {
        return Ok(None);
    }
    quiet_wayland_probe();
    match device {
        DeviceArg::Gpu => Gpu::new()
            .map(Some)
            .map_err(|e| Failure(format!("--device gpu: {e}"))),
        _ => match Gpu::new_hardware() {
            Ok(g) => Ok(Some(g)),
            Err(e) => {
                if !quiet {
                    eprintln!("gsi: no GPU ({e}); {doing} on the CPU");
                }
                Ok(None)
            }
        },
    }
}

/// Mesa's Vulkan drivers probe for a Wayland compositor while wgpu enumerates adapters,
/// and libwayland prints `error: XDG_RUNTIME_DIR is invalid or not set` when that variable
/// is unset (servers, CI, containers): a scary line about nothing. Point it at the temp
/// folder, where no compositor socket exists, so the probe fails quietly. Called before
/// the command starts any thread.
fn quiet_wayland_probe() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
}
