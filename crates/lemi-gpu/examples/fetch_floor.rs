//! What a per-pixel layer walk would cost on this adapter: one full-view pass whose fragment
//! shader makes `n` dependent texel fetches per pixel (each address depends on the texel before,
//! as a walk through a page table and an atlas does, and stays near the pixel's neighbours', as
//! the rays of neighbouring pixels meet a layer at neighbouring texels) from a 2048² RGBA8
//! texture, for several `n`, against the same pass without a fetch. Wall time per frame, median over `--reps` frames, each
//! submitted and waited for (on a software rasterizer the GPU time is nearly all of it).
//!
//! ```text
//! cargo run --release -p lemi-gpu --example fetch_floor -- [--size WxH] [--reps N]
//! ```
//!
//! `examples/layer_march` in lemi-eval counts how many layer planes and texels such a walk meets
//! per far-field pixel; this gives the price of each.

use std::time::Instant;

type Error = Box<dyn std::error::Error>;

const SHADER: &str = r#"
override FETCHES: u32 = 1u;

@group(0) @binding(0) var tex: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // one triangle over the whole view
    let x = f32((i << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(i & 2u) * 2.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    var p = vec2<u32>(pos.xy);
    var acc = vec4<f32>(0.0);
    for (var k = 0u; k < FETCHES; k++) {
        let t = textureLoad(tex, vec2<i32>(p & vec2<u32>(2047u)), 0);
        acc += t;
        // the next address depends on this texel, as a page table's entry gives the atlas
        // texel: a few texels away and one tile over (neighbouring pixels stay neighbours, as
        // the rays of neighbouring pixels meet a layer at neighbouring texels)
        p = vec2<u32>(pos.xy) + vec2<u32>(64u * (k + 1u) + u32(t.r * 7.0), 16u * (k + 1u) + u32(t.g * 7.0));
    }
    return acc / f32(FETCHES);
}
"#;

fn main() -> Result<(), Error> {
    let (mut width, mut height, mut reps) = (1280u32, 720u32, 20usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--size" => {
                let v = args.next().ok_or("--size needs WxH")?;
                (width, height) = lemi_core::camera::parse_size(&v)?;
            }
            "--reps" => reps = args.next().ok_or("--reps needs N")?.parse()?,
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    let Some(gpu) = lemi_testkit::gpu() else {
        return Ok(());
    };
    let (device, queue) = (&gpu.device, &gpu.queue);
    let side = 2048u32;
    // texels of a hash, so that the dependent addresses wander over the whole texture
    let mut texels = Vec::with_capacity((4 * side * side) as usize);
    let mut h = 0x9e37_79b9u32;
    for _ in 0..side * side {
        h ^= h << 13;
        h ^= h >> 17;
        h ^= h << 5;
        texels.extend_from_slice(&h.to_le_bytes());
    }
    let size = wgpu::Extent3d {
        width: side,
        height: side,
        depth_or_array_layers: 1,
    };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("fetch_floor texels"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &texels,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(4 * side),
            rows_per_image: Some(side),
        },
        size,
    );
    let target = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("fetch_floor target"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    let target_view = target.create_view(&Default::default());
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("fetch_floor"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("fetch_floor"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        }],
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("fetch_floor"),
        layout: &layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::TextureView(&texture.create_view(&Default::default())),
        }],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("fetch_floor"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    println!(
        "{}: {width}x{height}, dependent fetches from a {side}² RGBA8 texture, wall-time medians over {reps} frames",
        gpu.describe()
    );
    let mut base = f64::NAN;
    for n in [0u32, 1, 2, 5, 10, 20, 40] {
        let constants = [("FETCHES", n as f64)];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("fetch_floor"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    ..Default::default()
                },
                targets: &[Some(wgpu::TextureFormat::Rgba8Unorm.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let mut ms = Vec::with_capacity(reps + 2);
        for _ in 0..reps + 2 {
            let start = Instant::now();
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("fetch_floor"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &target_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.draw(0..3, 0..1);
            }
            queue.submit([encoder.finish()]);
            device.poll(wgpu::PollType::wait_indefinitely())?;
            ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        ms.drain(..2); // warm-up
        ms.sort_by(f64::total_cmp);
        let median = ms[ms.len() / 2];
        if n == 0 {
            base = median;
        }
        println!(
            "{n:>3} fetches a pixel: {median:6.2} ms ({:.2} ns a fetch and pixel beyond the empty pass)",
            if n == 0 {
                0.0
            } else {
                (median - base) * 1e6 / (n as f64 * width as f64 * height as f64)
            }
        );
    }
    Ok(())
}
