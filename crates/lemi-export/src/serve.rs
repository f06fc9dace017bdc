//! A minimal static file server for an export directory (`lemi serve`): HTTP/1.1 `GET` and `HEAD`
//! of the files below one directory, one thread per connection, `Connection: close`. Browsers do
//! not load ES modules or `fetch` files from `file://` URLs, so the web viewer needs one; nothing
//! else does, and `std::net` is enough for it (no dependency).
//!
//! Only paths inside the root are served: a request path is percent-decoded, split at `/`, and
//! refused if a component is empty after the first, `.` or `..` or holds a backslash or NUL.

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};

/// Serves `root` on `listener` until the process ends; `log` is told each request's status and
/// path.
pub fn serve(listener: TcpListener, root: &Path, log: bool) -> std::io::Result<()> {
    let root = root.to_path_buf();
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let root = root.clone();
        std::thread::spawn(move || {
            let _ = handle(stream, &root, log);
        });
    }
    Ok(())
}

fn handle(mut stream: TcpStream, root: &Path, log: bool) -> std::io::Result<()> {
    stream.set_read_timeout(Some(std::time::Duration::from_secs(30)))?;
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut request = String::new();
    reader.read_line(&mut request)?;
    // the headers are not used; read them so the client is not reset before the response
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line)? == 0 || line == "\r\n" || line == "\n" {
            break;
        }
    }
    let mut parts = request.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let head = method == "HEAD";
    if method != "GET" && !head {
        return respond(&mut stream, 405, "text/plain", b"only GET and HEAD\n", head);
    }
    let Some(path) = resolve(root, target) else {
        return respond(&mut stream, 400, "text/plain", b"bad path\n", head);
    };
    let path = if path.is_dir() {
        path.join("index.html")
    } else {
        path
    };
    let (status, body, kind) = match std::fs::read(&path) {
        Ok(b) => (200, b, content_type(&path)),
        Err(_) => (404, b"not found\n".to_vec(), "text/plain"),
    };
    if log {
        eprintln!("{status} {target}");
    }
    respond(&mut stream, status, kind, &body, head)
}

fn respond(
    stream: &mut TcpStream,
    status: u16,
    kind: &str,
    body: &[u8],
    head: bool,
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        _ => "Method Not Allowed",
    };
    let header = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-cache\r\nConnection: close\r\n\r\n",
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
