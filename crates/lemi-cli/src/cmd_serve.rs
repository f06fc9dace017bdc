//! `lemi serve PATH [--port 8080]`: the web viewer in a browser tab. PATH is a bundle (exported
//! first, near geometry included, into `-o DIR`, default `PATH-web`) or an export directory (one
//! holding `cells.json`); the viewer is copied in and the directory served over HTTP on
//! localhost. Everything the page loads comes from that directory: it works offline.
//! `--textures ktx2` exports a block-compressed bundle's KTX2 textures as they are.

use std::net::TcpListener;
use std::path::PathBuf;

use anyhow::{bail, Context};

#[derive(clap::Args)]
pub struct Args {
    /// A bundle directory (holds manifest.json) or an export directory (holds cells.json).
    pub path: PathBuf,
    /// Port to listen on (0: any free port; the URL is printed).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Where to export a bundle (default: PATH-web beside it).
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Export without the near geometry (no scene is loaded).
    #[arg(long)]
    pub no_near: bool,
    /// Texture format of the exported cells: png (decoded, any browser) or ktx2 (a bundle baked
    /// with --texture-format bc7 or bc1: its blocks as stored, for browsers whose WebGL has
    /// the format, e.g. desktop browsers with S3TC for BC1 and BPTC for BC7; uastc or etc1s:
    /// its Basis Universal files, transcoded by the browser).
    #[arg(long, value_enum, default_value = "png")]
    pub textures: crate::cmd_export::TexturesArg,
    /// How the exported cells store vertex and index data (as `lemi export --geometry`):
    /// meshopt (EXT_meshopt_compression), meshopt-v1 (KHR_meshopt_compression, smaller; three.js
    /// r179 and later, as the viewer's) or plain.
    #[arg(long, value_enum, default_value = "meshopt")]
    pub geometry: crate::cmd_export::GeometryArg,
    /// The scene to use instead of the bundle manifest's sources (checked against its fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// Where the web viewer and its node packages are (default: lemi's source tree's `web`).
    #[arg(long, value_name = "DIR")]
    pub web_dir: Option<PathBuf>,
    /// Print each request.
    #[arg(long)]
    pub verbose: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dir = if crate::bundle_view::is_bundle(&args.path.to_string_lossy()) {
        let out = args.output.clone().unwrap_or_else(|| {
            let mut name = args
                .path
                .file_name()
                .map(|n| n.to_os_string())
                .unwrap_or_else(|| "bundle".into());
            name.push("-web");
            args.path.with_file_name(name)
        });
        let summary = crate::cmd_export::export(
            &args.path,
            &out,
            &[],
            crate::cmd_export::Storage {
                textures: args.textures.into(),
                geometry: args.geometry.into(),
            },
            !args.no_near,
            &args.scene_override,
            false,
        )?;
        eprintln!(
            "exported   {} cells of {} into {}",
            summary.index.cells.len(),
            args.path.display(),
            out.display()
        );
        out
    } else if args.path.join(lemi_export::INDEX_FILE).is_file() {
        if args.textures != crate::cmd_export::TexturesArg::Png
            || args.geometry != crate::cmd_export::GeometryArg::Meshopt
        {
            bail!(
                "--textures and --geometry apply to a bundle, not to an export directory ({} was \
                 exported already)",
                args.path.display()
            );
        }
        args.path.clone()
    } else {
        bail!(
            "{}: neither a bundle (no manifest.json) nor an export directory (no {})",
            args.path.display(),
            lemi_export::INDEX_FILE
        );
    };
    crate::web::install_viewer(&dir, args.web_dir.as_deref())?;
    let listener = TcpListener::bind((args.host.as_str(), args.port))
        .with_context(|| format!("--host {} --port {}: cannot listen", args.host, args.port))?;
    let addr = listener.local_addr()?;
    // stdout's first line is the URL (tests and scripts read it)
    println!("http://{addr}/");
    eprintln!(
        "serving    {} at http://{addr}/ (Ctrl-C to stop)",
        dir.display()
    );
    lemi_export::serve::serve(listener, &dir, args.verbose)?;
    Ok(())
}
