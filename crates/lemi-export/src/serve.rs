//! A minimal static file server for an export directory (`lemi serve`): HTTP/1.1 `GET` and `HEAD`
//! of the files below one directory, one thread per connection, `Connection: close`. Browsers do
//! not load ES modules or `fetch` files from `file://` URLs, so the web viewer needs one; nothing
//! else does, and `std::net` is enough for it.
//!
//! A client that accepts gzip (`Accept-Encoding`, as every browser sends) gets the files that
//! shrink with it (cells, JSON, scripts: [`compressible`]) gzip-encoded, as a production web
//! server (nginx `gzip_static`, a CDN) would serve an export: a cell `.glb` travels 12–26 %
//! smaller (docs/EXPORT.md, "Bytes"). Each file is compressed once (flate2, the workspace's
//! deflate) and kept while it is unchanged on disk, up to [`GZIP_CACHE_BYTES`].
//!
//! Only paths inside the root are served: a request path is percent-decoded, split at `/`, and
//! refused if a component is empty after the first, `.` or `..` or holds a backslash or NUL.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::SystemTime;

/// The most gzip-encoded bytes the server keeps; past it the cache starts over.
pub const GZIP_CACHE_BYTES: usize = 256 << 20;

/// A file compressed once, and the modification time and length of the file it was made from.
struct Gzipped {
    modified: Option<SystemTime>,
    len: u64,
    gz: Arc<Vec<u8>>,
}

/// The files compressed so far, by path.
#[derive(Default)]
struct GzipCache {
    files: HashMap<PathBuf, Gzipped>,
    bytes: usize,
}

/// Serves `root` on `listener` until the process ends; `log` is told each request's status and
/// path.
pub fn serve(listener: TcpListener, root: &Path, log: bool) -> std::io::Result<()> {
    let root = root.to_path_buf();
    let cache = Arc::new(Mutex::new(GzipCache::default()));
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let (root, cache) = (root.clone(), cache.clone());
        std::thread::spawn(move || {
            let _ = handle(stream, &root, &cache, log);
        });
    }
    Ok(())
}

fn handle(
    mut stream: TcpStream,
    root: &Path,
    cache: &Mutex<GzipCache>,
    log: bool,
) -> std::io::Result<()> {
    stream.set_read_timeout(Some(std::time::Duration::from_secs(30)))?;
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut request = String::new();
    reader.read_line(&mut request)?;
    // read every header so the client is not reset before the response; keep Accept-Encoding
    let mut gzip_ok = false;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line)? == 0 || line == "\r\n" || line == "\n" {
            break;
        }
        if let Some((name, value)) = line.split_once(':') {
            if name.trim().eq_ignore_ascii_case("accept-encoding") {
                gzip_ok |= accepts_gzip(value);
            }
        }
    }
    let mut parts = request.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let head = method == "HEAD";
    if method != "GET" && !head {
        return respond(
            &mut stream,
            405,
            "text/plain",
            b"only GET and HEAD\n",
            None,
            head,
        );
    }
    let Some(path) = resolve(root, target) else {
        return respond(&mut stream, 400, "text/plain", b"bad path\n", None, head);
    };
    let path = if path.is_dir() {
        path.join("index.html")
    } else {
        path
    };
    let Ok(body) = std::fs::read(&path) else {
        if log {
            eprintln!("404 {target}");
        }
        return respond(&mut stream, 404, "text/plain", b"not found\n", None, head);
    };
    let kind = content_type(&path);
    let encoded = if gzip_ok && compressible(&path) {
        gzip_cached(cache, &path, &body)
    } else {
        None
    };
    if log {
        let how = if encoded.is_some() { " (gzip)" } else { "" };
        eprintln!("200 {target}{how}");
    }
    match encoded {
        Some(gz) => respond(&mut stream, 200, kind, &gz, Some("gzip"), head),
        None => respond(&mut stream, 200, kind, &body, None, head),
    }
}

/// Whether an `Accept-Encoding` value admits gzip (`gzip` or `*`, unless its `q` is 0).
pub fn accepts_gzip(value: &str) -> bool {
    value.split(',').any(|item| {
        let mut parts = item.split(';');
        let coding = parts.next().unwrap_or("").trim();
        let q_zero = parts.any(|p| {
            p.trim()
                .strip_prefix("q=")
                .and_then(|q| q.trim().parse::<f32>().ok())
                .is_some_and(|q| q <= 0.0)
        });
        (coding.eq_ignore_ascii_case("gzip") || coding == "*") && !q_zero
    })
}

/// Whether a file is worth gzip-encoding: the cells, the index and the viewer's text, not the
/// images, which are compressed already (PNG; KTX2 with Zstandard or Basis).
pub fn compressible(path: &Path) -> bool {
    matches!(
        path.extension().and_then(|e| e.to_str()).unwrap_or(""),
        "glb" | "gltf" | "json" | "js" | "mjs" | "html" | "css" | "wasm" | "bin"
    )
}

/// `body` gzip-encoded, from the cache while the file is unchanged; `None` where gzip does not
/// make it smaller.
fn gzip_cached(cache: &Mutex<GzipCache>, path: &Path, body: &[u8]) -> Option<Arc<Vec<u8>>> {
    let modified = std::fs::metadata(path).and_then(|m| m.modified()).ok();
    let len = body.len() as u64;
    if let Ok(c) = cache.lock() {
        if let Some(g) = c.files.get(path) {
            if g.modified == modified && g.len == len && modified.is_some() {
                return (g.gz.len() < body.len()).then(|| g.gz.clone());
            }
        }
    }
    let gz = Arc::new(gzip(body).ok()?);
    if let Ok(mut c) = cache.lock() {
        if c.bytes + gz.len() > GZIP_CACHE_BYTES {
            c.files.clear();
            c.bytes = 0;
        }
        c.bytes += gz.len();
        let entry = Gzipped {
            modified,
            len,
            gz: gz.clone(),
        };
        if let Some(old) = c.files.insert(path.to_path_buf(), entry) {
            c.bytes -= old.gz.len();
        }
    }
    (gz.len() < body.len()).then_some(gz)
}

/// `data` as a gzip stream (best compression: each file is compressed once).
pub fn gzip(data: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut enc = flate2::write::GzEncoder::new(
        Vec::with_capacity(data.len() / 2),
        flate2::Compression::best(),
    );
    enc.write_all(data)?;
    enc.finish()
}

fn respond(
    stream: &mut TcpStream,
    status: u16,
    kind: &str,
    body: &[u8],
    encoding: Option<&str>,
    head: bool,
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        _ => "Method Not Allowed",
    };
    let encoding = encoding
        .map(|e| format!("Content-Encoding: {e}\r\n"))
        .unwrap_or_default();
    let header = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\n{encoding}Vary: Accept-Encoding\r\nCache-Control: no-cache\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(header.as_bytes())?;
    if !head {
        stream.write_all(body)?;
    }
    stream.flush()
}

/// The file a request target names below `root`, or `None` for a path that would leave it.
pub fn resolve(root: &Path, target: &str) -> Option<PathBuf> {
    let path = target.split(['?', '#']).next()?;
    let path = path.strip_prefix('/')?;
    let decoded = percent_decode(path)?;
    let mut out = root.to_path_buf();
    for (i, part) in decoded.split('/').enumerate() {
        if part.is_empty() && i == 0 {
            continue;
        }
        if part.is_empty() {
            // a trailing slash names a directory
            if decoded.ends_with('/') {
                continue;
            }
            return None;
        }
        if part == "." || part == ".." || part.contains(['\\', '\0']) {
            return None;
        }
        out.push(part);
    }
    Some(out)
}

fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "json" => "application/json",
        "glb" => "model/gltf-binary",
        "png" => "image/png",
        "ktx2" => "image/ktx2",
        "wasm" => "application/wasm",
        "css" => "text/css",
        _ => "application/octet-stream",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_encoding_is_read_as_browsers_send_it() {
        for yes in [
            "gzip, deflate, br, zstd",
            "br;q=1.0, gzip;q=0.8",
            " GZIP",
            "*",
            "identity, *;q=0.5",
        ] {
            assert!(accepts_gzip(yes), "{yes}");
        }
        for no in [
            "",
            "identity",
            "br",
            "gzip;q=0",
            "gzip; q=0.0, br",
            "x-gzip2",
        ] {
            assert!(!accepts_gzip(no), "{no}");
        }
        assert!(compressible(Path::new("cells/0_0_0.glb")));
        assert!(compressible(Path::new("cells.json")));
        assert!(!compressible(Path::new("t/0.png")));
        assert!(!compressible(Path::new("t/0.ktx2")));
    }

    /// One request to a running server: the status line and headers, and the body.
    fn get(addr: std::net::SocketAddr, request: &str) -> (String, Vec<u8>) {
        use std::io::Read;
        let mut s = TcpStream::connect(addr).unwrap();
        s.write_all(request.as_bytes()).unwrap();
        let mut all = Vec::new();
        s.read_to_end(&mut all).unwrap();
        let split = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        let head = String::from_utf8(all[..split].to_vec()).unwrap();
        (head, all[split + 4..].to_vec())
    }

    #[test]
    fn files_go_out_gzip_encoded_to_clients_that_accept_it() {
        use std::io::Read;
        let root = std::env::temp_dir().join(format!("lemi-serve-{}", std::process::id()));
        std::fs::create_dir_all(&root).unwrap();
        // a cell-like file that compresses, and an image that must go out as it is
        let cell: Vec<u8> = (0..200_000u32).map(|i| (i % 251 / 7) as u8).collect();
        std::fs::write(root.join("c.glb"), &cell).unwrap();
        std::fs::write(root.join("t.png"), &cell[..1000]).unwrap();
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let served = root.clone();
        std::thread::spawn(move || serve(listener, &served, false));

        let ask = "GET /c.glb HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip, deflate, br\r\n\r\n";
        for _ in 0..2 {
            // the second answer comes from the cache and must be the same
            let (head, body) = get(addr, ask);
            assert!(head.starts_with("HTTP/1.1 200"), "{head}");
            assert!(head.contains("Content-Encoding: gzip"), "{head}");
            assert!(
                head.contains(&format!("Content-Length: {}", body.len())),
                "{head}"
            );
            assert!(body.len() < cell.len() / 4, "{} bytes", body.len());
            let mut plain = Vec::new();
            flate2::read::GzDecoder::new(&body[..])
                .read_to_end(&mut plain)
                .unwrap();
            assert_eq!(plain, cell);
        }
        // a HEAD says the same without the body
        let (head, body) = get(addr, &ask.replace("GET", "HEAD"));
        assert!(
            head.contains("Content-Encoding: gzip") && body.is_empty(),
            "{head}"
        );
        // without Accept-Encoding, or with gzip refused, the bytes as stored
        for ask in [
            "GET /c.glb HTTP/1.1\r\nHost: x\r\n\r\n",
            "GET /c.glb HTTP/1.1\r\nAccept-Encoding: gzip;q=0\r\n\r\n",
        ] {
            let (head, body) = get(addr, ask);
            assert!(!head.contains("Content-Encoding"), "{head}");
            assert_eq!(body, cell);
        }
        // a changed file is compressed again, not served stale from the cache
        let changed: Vec<u8> = cell.iter().rev().copied().collect();
        std::fs::write(root.join("c.glb"), &changed[..150_000]).unwrap();
        let (_, body) = get(addr, ask);
        let mut plain = Vec::new();
        flate2::read::GzDecoder::new(&body[..])
            .read_to_end(&mut plain)
            .unwrap();
        assert_eq!(plain, changed[..150_000]);
        // images are compressed already: as stored, whatever the client accepts
        let (head, body) = get(addr, &ask.replace("c.glb", "t.png"));
        assert!(!head.contains("Content-Encoding"), "{head}");
        assert_eq!(body, cell[..1000]);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn paths_stay_inside_the_root() {
        let root = Path::new("/srv/x");
        assert_eq!(resolve(root, "/"), Some(root.to_path_buf()));
        assert_eq!(
            resolve(root, "/cells/0_0_0.glb?x=1"),
            Some(root.join("cells/0_0_0.glb"))
        );
        assert_eq!(resolve(root, "/a%20b.js"), Some(root.join("a b.js")));
        for bad in [
            "/../etc/passwd",
            "/cells/../../x",
            "/%2e%2e/x",
            "x",
            "/a//b",
            "/a\\b",
            "/%zz",
        ] {
            assert_eq!(resolve(root, bad), None, "{bad}");
        }
    }
}
