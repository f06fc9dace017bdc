//! Device setup: finds an adapter (a real GPU, or Mesa's lavapipe/llvmpipe software rasterizers),
//! honouring `WGPU_BACKEND` / `WGPU_ADAPTER_NAME` / `WGPU_POWER_PREF`, and opens a device with the
//! adapter's own limits so that large buffers are allowed. With no adapter, one clear error says what
//! to install.

use std::fmt;

use thiserror::Error;

/// Everything that can go wrong on the GPU side.
#[derive(Debug, Error)]
pub enum GpuError {
    /// No adapter for the requested backends; the message says what to install.
    #[error("{0}")]
    NoAdapter(String),
    #[error("could not open a device on adapter {adapter}: {message}")]
    Device { adapter: String, message: String },
    /// A validation or out-of-memory error reported by wgpu while doing `what`.
    #[error("GPU error while {what}: {message}")]
    Wgpu { what: String, message: String },
    /// A request the adapter cannot satisfy (image too large, …).
    #[error("{0}")]
    Limit(String),
    /// Invalid input data (bad texture size, material index out of range, bad lighting, …).
    #[error("{0}")]
    Invalid(String),
    /// A near list entry naming a mesh or triangle the scene does not have (the message is the
    /// [`ExtractError`](lemi_core::scene::ExtractError)'s).
    #[error(transparent)]
    Extract(#[from] lemi_core::scene::ExtractError),
    #[error("reading the rendered image back failed: {0}")]
    Readback(String),
}

/// Which wgpu backend to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BackendChoice {
    /// `WGPU_BACKEND` if set (wgpu's own parser: `vulkan`, `gl`, `metal`, `dx12`, comma lists), else
    /// the primary backends (Vulkan, Metal, DX12) and then GL.
    #[default]
    Auto,
    Vulkan,
    Gl,
    Metal,
    Dx12,
}

impl BackendChoice {
    /// Parses `auto`, `vulkan`/`vk`, `gl`/`gles`/`opengl`, `metal`, `dx12`.
    pub fn parse(s: &str) -> Result<BackendChoice, GpuError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(BackendChoice::Auto),
            "vulkan" | "vk" => Ok(BackendChoice::Vulkan),
            "gl" | "gles" | "opengl" => Ok(BackendChoice::Gl),
            "metal" | "mtl" => Ok(BackendChoice::Metal),
            "dx12" | "d3d12" => Ok(BackendChoice::Dx12),
            other => Err(GpuError::Invalid(format!(
                "unknown backend `{other}`: expected auto, vulkan, gl, metal or dx12"
            ))),
        }
    }

    /// The backend sets to try, in order.
    pub(crate) fn attempts(self) -> Vec<wgpu::Backends> {
        match self {
            BackendChoice::Auto => match wgpu::Backends::from_env() {
                Some(b) => vec![b],
                None => vec![wgpu::Backends::PRIMARY, wgpu::Backends::GL],
            },
            BackendChoice::Vulkan => vec![wgpu::Backends::VULKAN],
            BackendChoice::Gl => vec![wgpu::Backends::GL],
            BackendChoice::Metal => vec![wgpu::Backends::METAL],
            BackendChoice::Dx12 => vec![wgpu::Backends::DX12],
        }
    }
}

impl fmt::Display for BackendChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            BackendChoice::Auto => match std::env::var("WGPU_BACKEND") {
                Ok(v) => return write!(f, "WGPU_BACKEND={v}"),
                Err(_) => "auto (Vulkan/Metal/DX12, then GL)",
            },
            BackendChoice::Vulkan => "vulkan",
            BackendChoice::Gl => "gl",
            BackendChoice::Metal => "metal",
            BackendChoice::Dx12 => "dx12",
        };
        f.write_str(s)
    }
}

/// The one error message for a machine without a usable adapter. `tried` names the backends tried.
pub fn no_adapter_message(tried: &str) -> String {
    format!(
        "no GPU adapter found (backends tried: {tried}). lemi renders with wgpu and needs a GPU driver \
         or Mesa's software rasterizers: install `mesa-vulkan-drivers` (Vulkan via lavapipe) or Mesa's \
         EGL/GL (`libegl1 libgl1-mesa-dri`, GL via llvmpipe), e.g. `apt-get install \
         mesa-vulkan-drivers libegl1 libgl1-mesa-dri`; or choose another backend with \
         WGPU_BACKEND=vulkan|gl (or `--backend`)"
    )
}

/// An open device and its queue.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    pub(crate) layouts: crate::shading::Layouts,
}

impl fmt::Debug for Gpu {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Gpu")
            .field("adapter", &self.describe())
            .finish()
    }
}

impl Gpu {
    /// The adapter for test suites: `Some` when one exists; `None` (the test is skipped, with a
    /// printed reason) when none exists and `LEMI_SKIP_GPU_TESTS=1`; otherwise it panics with the
    /// install hint, so a CI machine without drivers fails loudly instead of skipping silently.
    pub fn for_tests() -> Option<Gpu> {
        match Gpu::new(BackendChoice::Auto) {
            Ok(g) => Some(g),
            Err(e) => {
                if std::env::var("LEMI_SKIP_GPU_TESTS").as_deref() == Ok("1") {
                    // Straight to stderr: the test harness captures `eprintln!` of passing
                    // tests, and a skip must show in the run's output.
                    use std::io::Write;
                    let test = std::thread::current();
                    let line = format!(
                        "SKIPPED {}: no GPU adapter (LEMI_SKIP_GPU_TESTS=1): {e}\n",
                        test.name().unwrap_or("a GPU test")
                    );
                    let _ = std::io::stderr().write_all(line.as_bytes());
                    None
                } else {
                    panic!("{e}");
                }
            }
        }
    }

    /// Finds an adapter for `choice` and opens a device with the adapter's limits.
    pub fn new(choice: BackendChoice) -> Result<Gpu, GpuError> {
        pollster::block_on(Self::new_async(choice))
    }

    async fn new_async(choice: BackendChoice) -> Result<Gpu, GpuError> {
        let wanted_name = std::env::var("WGPU_ADAPTER_NAME")
            .ok()
            .map(|s| s.to_lowercase());
        let mut seen = Vec::new();
        for backends in choice.attempts() {
            if backends.is_empty() {
                continue;
            }
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
            desc.backends = backends;
            let instance = wgpu::Instance::new(desc);
            let adapter = match &wanted_name {
                Some(name) => {
                    let adapters = instance.enumerate_adapters(backends).await;
                    for a in &adapters {
                        seen.push(a.get_info().name);
                    }
                    adapters
                        .into_iter()
                        .find(|a| a.get_info().name.to_lowercase().contains(name.as_str()))
                }
                None => instance
                    .request_adapter(&wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::from_env().unwrap_or_default(),
                        force_fallback_adapter: false,
                        compatible_surface: None,
                        ..Default::default()
                    })
                    .await
                    .ok(),
            };
            let Some(adapter) = adapter else { continue };
            let info = adapter.get_info();
            // Timestamp queries when the adapter has them (lavapipe does; llvmpipe's GL does not):
            // the renderers time their passes with them (`Renderer::last_gpu_ms`). BC texture
            // compression when it has it (lavapipe does): block-compressed macro-textures are
            // then uploaded as they are stored (`ImpostorCell::begin_upload`).
            let features = adapter.features()
                & (wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TEXTURE_COMPRESSION_BC);
            let (device, queue) = adapter
                .request_device(&wgpu::DeviceDescriptor {
                    label: Some("lemi"),
                    required_features: features,
                    required_limits: adapter.limits(),
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::Device {
                    adapter: format!("{} ({:?})", info.name, info.backend),
                    message: e.to_string(),
                })?;
            let layouts = crate::shading::Layouts::new(&device);
            return Ok(Gpu {
                device,
                queue,
                info,
                layouts,
            });
        }
        if let Some(name) = wanted_name {
            return Err(GpuError::NoAdapter(format!(
                "WGPU_ADAPTER_NAME={name} matches none of the adapters found ({}); {}",
                if seen.is_empty() {
                    "none".to_string()
                } else {
                    seen.join(", ")
                },
                no_adapter_message(&choice.to_string())
            )));
        }
        Err(GpuError::NoAdapter(no_adapter_message(&choice.to_string())))
    }

    /// A `Gpu` from a device opened elsewhere (the window surface's adapter, `crate::surface`).
    pub(crate) fn from_parts(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
    ) -> Gpu {
        let layouts = crate::shading::Layouts::new(&device);
        Gpu {
            device,
            queue,
            info,
            layouts,
        }
    }

    /// The adapter's description.
    pub fn info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// `"llvmpipe (LLVM 19.1.7, 256 bits) (Vulkan, Cpu)"`: adapter name, backend and type.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// The device's limits.
    pub fn limits(&self) -> wgpu::Limits {
        self.device.limits()
    }

    /// Whether the device has timestamp queries, so that the renderers report GPU times
    /// ([`crate::Renderer::last_gpu_ms`], [`crate::ImpostorRenderer::last_gpu_ms`]).
    pub fn has_timestamps(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Whether the device samples macro-textures of `format` as they are stored (BC7 and BC1
    /// need `TEXTURE_COMPRESSION_BC`, requested whenever the adapter has it); elsewhere they are
    /// decoded to RGBA8 on the CPU.
    pub fn has_block_format(&self, format: lemi_core::compress::BlockFormat) -> bool {
        match format {
            lemi_core::compress::BlockFormat::Bc7 | lemi_core::compress::BlockFormat::Bc1 => self
                .device
                .features()
                .contains(wgpu::Features::TEXTURE_COMPRESSION_BC),
        }
    }

    /// The bind group layouts of the shared shading module (group 0: globals, group 1: material).
    pub fn globals_layout(&self) -> &wgpu::BindGroupLayout {
        &self.layouts.globals
    }

    pub fn material_layout(&self) -> &wgpu::BindGroupLayout {
        &self.layouts.material
    }

    /// Runs `f` inside validation and out-of-memory error scopes and turns a captured error into a
    /// [`GpuError::Wgpu`] naming `what`.
    pub fn scoped<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        scoped(&self.device, what, f)
    }
}

/// Runs `f` inside validation and out-of-memory error scopes of `device` and turns a captured error
/// into a [`GpuError::Wgpu`] naming `what`.
pub(crate) fn scoped<T>(
    device: &wgpu::Device,
    what: &str,
    f: impl FnOnce() -> T,
) -> Result<T, GpuError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let v = pollster::block_on(validation.pop());
    let o = pollster::block_on(oom.pop());
    match v.or(o) {
        Some(e) => Err(GpuError::Wgpu {
            what: what.to_string(),
            message: e.to_string(),
        }),
        None => Ok(out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_adapter_message_says_what_to_install() {
        let m = no_adapter_message("vulkan");
        assert!(m.starts_with("no GPU adapter found (backends tried: vulkan)"));
        for needle in [
            "mesa-vulkan-drivers",
            "lavapipe",
            "libegl1 libgl1-mesa-dri",
            "llvmpipe",
            "WGPU_BACKEND",
        ] {
            assert!(m.contains(needle), "missing {needle}: {m}");
        }
        assert_eq!(
            GpuError::NoAdapter(m.clone()).to_string(),
            m,
            "the error shows the message unchanged"
        );
    }

    #[test]
    fn backend_names_parse() {
        assert_eq!(
            BackendChoice::parse("Vulkan").ok(),
            Some(BackendChoice::Vulkan)
        );
        assert_eq!(BackendChoice::parse("gl").ok(), Some(BackendChoice::Gl));
        assert_eq!(BackendChoice::parse("auto").ok(), Some(BackendChoice::Auto));
        let e = BackendChoice::parse("glide").err().map(|e| e.to_string());
        assert!(e.is_some_and(|e| e.contains("glide") && e.contains("vulkan")));
    }
}
