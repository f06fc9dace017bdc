//! PLY reader (ASCII, binary little- and big-endian, optionally gzip-compressed), based on
//! Greg Turk's "The PLY Polygon File Format" (1994), the format the Stanford 3D Scanning
//! Repository uses.
//!
//! A small strict reader rather than a crate: it streams the body once straight into a
//! [`lemi_core::Mesh`] (no per-element maps), so the 871,414-face Stanford dragon parses in well
//! under a second, and every malformed or truncated input ends as an error saying where.
//!
//! Read: `vertex` positions `x y z` (any numeric type), optional normals `nx ny nz`, optional
//! colours `red green blue [alpha]` (integer types as 0..=255 sRGB-encoded values, converted to
//! linear; float types as 0..=1), optional texture coordinates `u v` / `s t` /
//! `texture_u texture_v`; `face` polygons from a `vertex_indices` or `vertex_index` list of any
//! size, fan-triangulated. Every other element and property is parsed and ignored. Indices that are
//! negative, fractional or out of range become an out-of-range index, which
//! [`lemi_core::SceneBuilder`] drops and counts.

use std::io::Read;
use std::path::Path;

use lemi_core::{Mesh, SceneBuilder, UpAxis, Vertex};

use super::{malformed, progress, read_file, srgb8_to_linear8, ImportReport};
use crate::{LoadOptions, SceneError};

/// Faces between two progress reports.
const PROGRESS_EVERY: u64 = 100_000;

pub(super) fn load(
    path: &Path,
    gz: bool,
    options: &LoadOptions,
    builder: &mut SceneBuilder,
    _report: &mut ImportReport,
) -> Result<(), SceneError> {
    let raw = read_file(path)?;
    let data = if gz {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(raw.as_slice())
            .read_to_end(&mut out)
            .map_err(|e| malformed(path, format!("gzip: {e}")))?;
        out
    } else {
        raw
    };
    let what = path.display().to_string();
    let mesh = parse(&data, options.up, &mut |done, total| {
        progress(options, &what, done, total)
    })
    .map_err(|m| malformed(path, m))?;
    builder.add_mesh(mesh);
    Ok(())
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Ty {
    fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Ty::F32 | Ty::F64)
    }
}

#[derive(Clone, Debug)]
enum PropKind {
    Scalar(Ty),
    List { count: Ty, item: Ty },
}

#[derive(Clone, Debug)]
struct Prop {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Prop>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body: usize,
}

fn parse_header(data: &[u8]) -> Result<Header, String> {
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut next_line = |pos: &mut usize| -> Option<String> {
        if *pos >= data.len() {
            return None;
        }
        let rest = &data[*pos..];
        let end = rest.iter().position(|&b| b == b'\n');
        let (line, adv) = match end {
            Some(e) => (&rest[..e], e + 1),
            None => (rest, rest.len()),
        };
        *pos += adv;
        line_no += 1;
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        Some(String::from_utf8_lossy(line).into_owned())
    };
    match next_line(&mut pos) {
        Some(l) if l.trim_end() == "ply" => {}
        _ => return Err("not a PLY file (missing `ply` magic line)".into()),
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(line) = next_line(&mut pos) else {
            return Err("header has no `end_header` line".into());
        };
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        let bad = |what: &str| format!("header line `{}`: {what}", line.trim());
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                let f = match words.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    _ => return Err(bad("unknown format")),
                };
                if words.get(2).copied() != Some("1.0") {
                    return Err(bad("unsupported version (expected 1.0)"));
                }
                format = Some(f);
            }
            Some("element") => {
                let (Some(name), Some(count), None) = (words.get(1), words.get(2), words.get(3))
                else {
                    return Err(bad("expected `element NAME COUNT`"));
                };
                let count: u64 = count.parse().map_err(|_| bad("bad element count"))?;
                elements.push(Element {
                    name: (*name).to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(bad("property before any element"));
                };
                let prop = match words.get(1).copied() {
                    Some("list") => {
                        let (Some(c), Some(i), Some(name), None) =
                            (words.get(2), words.get(3), words.get(4), words.get(5))
                        else {
                            return Err(bad("expected `property list COUNT_TYPE ITEM_TYPE NAME`"));
                        };
                        let count = Ty::parse(c).ok_or_else(|| bad("unknown type"))?;
                        let item = Ty::parse(i).ok_or_else(|| bad("unknown type"))?;
                        if count.is_float() {
                            return Err(bad("list count type must be an integer type"));
                        }
                        Prop {
                            name: (*name).to_string(),
                            kind: PropKind::List { count, item },
                        }
                    }
                    Some(t) => {
                        let (Some(name), None) = (words.get(2), words.get(3)) else {
                            return Err(bad("expected `property TYPE NAME`"));
                        };
                        Prop {
                            name: (*name).to_string(),
                            kind: PropKind::Scalar(
                                Ty::parse(t).ok_or_else(|| bad("unknown type"))?,
                            ),
                        }
                    }
                    None => return Err(bad("expected `property TYPE NAME`")),
                };
                element.props.push(prop);
            }
            Some("end_header") => break,
            Some(_) => return Err(bad("unknown header keyword")),
        }
    }
    let format = format.ok_or("header has no `format` line")?;
    Ok(Header {
        format,
        elements,
        body: pos,
    })
}

/// The body, read value by value.
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    format: Format,
}

impl Body<'_> {
    /// Reads the next value of type `ty` as `f64` (exact for every PLY integer type).
    #[inline]
    fn next(&mut self, ty: Ty) -> Option<f64> {
        match self.format {
            Format::Ascii => self.next_ascii(ty),
            Format::BinaryLe => self.next_binary::<false>(ty),
            Format::BinaryBe => self.next_binary::<true>(ty),
        }
    }

    #[inline]
    fn next_binary<const BE: bool>(&mut self, ty: Ty) -> Option<f64> {
        let n = ty.size();
        let bytes = self.data.get(self.pos..self.pos + n)?;
        self.pos += n;
        macro_rules! num {
            ($t:ty, $k:literal) => {{
                let mut a = [0u8; $k];
                a.copy_from_slice(bytes);
                if BE {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        Some(match ty {
            Ty::I8 => bytes[0] as i8 as f64,
            Ty::U8 => bytes[0] as f64,
            Ty::I16 => num!(i16, 2),
            Ty::U16 => num!(u16, 2),
            Ty::I32 => num!(i32, 4),
            Ty::U32 => num!(u32, 4),
            Ty::F32 => num!(f32, 4),
            Ty::F64 => num!(f64, 8),
        })
    }

    /// `None` at the end of the data or on a token that is not a number of that type.
    #[inline]
    fn next_ascii(&mut self, ty: Ty) -> Option<f64> {
        let d = self.data;
        let mut i = self.pos;
        while i < d.len() && d[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < d.len() && !d[i].is_ascii_whitespace() {
            i += 1;
        }
        self.pos = i;
        if start == i {
            return None;
        }
        let tok = std::str::from_utf8(&d[start..i]).ok()?;
        if ty.is_float() {
            tok.parse::<f64>().ok()
        } else {
            tok.parse::<i64>().ok().map(|v| v as f64)
        }
    }

    fn describe_failure(&self, element: &str, item: u64, count: u64) -> String {
        // A binary value fails to read only at the end of the data.
        if self.format != Format::Ascii || self.pos >= self.data.len() {
            format!("truncated: data ends in element `{element}` {item} of {count}")
        } else {
            format!("bad value in element `{element}` {item} of {count}")
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    R,
    G,
    B,
    A,
    U,
    V,
    Other,
}

fn role(name: &str) -> Role {
    match name {
        "x" => Role::X,
        "y" => Role::Y,
        "z" => Role::Z,
        "nx" => Role::Nx,
        "ny" => Role::Ny,
        "nz" => Role::Nz,
        "red" | "diffuse_red" => Role::R,
        "green" | "diffuse_green" => Role::G,
        "blue" | "diffuse_blue" => Role::B,
        "alpha" | "diffuse_alpha" => Role::A,
        "u" | "s" | "texture_u" | "texture_s" => Role::U,
        "v" | "t" | "texture_v" | "texture_t" => Role::V,
        _ => Role::Other,
    }
}

/// Scales a colour value of type `ty` to 0..=255.
fn color8(ty: Ty, v: f64) -> u8 {
    let scaled = match ty {
        Ty::F32 | Ty::F64 => v * 255.0,
        Ty::U16 => v / 257.0,
        _ => v,
    };
    if scaled.is_nan() {
        0
    } else {
        scaled.round().clamp(0.0, 255.0) as u8
    }
}

/// Converts a PLY index value to `u32`; anything invalid becomes `u32::MAX`, an out-of-range index
/// (vertex counts are limited below it).
#[inline]
fn index(v: f64) -> u32 {
    if v >= 0.0 && v < u32::MAX as f64 && v.fract() == 0.0 {
        v as u32
    } else {
        u32::MAX
    }
}

/// Parses a whole (decompressed) PLY file into one mesh with material 0 (the builder adds a
/// default material). `progress(done, total)` is called every [`PROGRESS_EVERY`] faces.
pub(crate) fn parse(
    data: &[u8],
    up: UpAxis,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Mesh, String> {
    let header = parse_header(data)?;
    let mut body = Body {
        data,
        pos: header.body,
        format: header.format,
    };
    let remaining = data.len().saturating_sub(header.body);
    let mut mesh = Mesh::default();
    let mut seen_vertex = false;
    let mut seen_face = false;
    for el in &header.elements {
        // Smallest possible encoding of one item, to cap allocations by what the data can hold.
        let min_item = match header.format {
            Format::Ascii => 2 * el.props.len().max(1),
            _ => el
                .props
                .iter()
                .map(|p| match p.kind {
                    PropKind::Scalar(t) => t.size(),
                    PropKind::List { count, .. } => count.size(),
                })
                .sum::<usize>()
                .max(1),
        };
        let cap = (el.count as usize).min(remaining / min_item + 1);
        if el.name == "vertex" && !seen_vertex {
            seen_vertex = true;
            if el.count >= u32::MAX as u64 {
                return Err(format!("too many vertices ({})", el.count));
            }
            let roles: Vec<(Role, &PropKind)> =
                el.props.iter().map(|p| (role(&p.name), &p.kind)).collect();
            for r in [Role::X, Role::Y, Role::Z] {
                if !roles
                    .iter()
                    .any(|(q, k)| *q == r && matches!(k, PropKind::Scalar(_)))
                {
                    return Err(format!(
                        "element `vertex` has no scalar property `{}`",
                        match r {
                            Role::X => "x",
                            Role::Y => "y",
                            _ => "z",
                        }
                    ));
                }
            }
            mesh.vertices.reserve(cap);
            for item in 0..el.count {
                let mut v = Vertex::new([0.0; 3], [0.0; 3], [0.0; 2], [255; 4]);
                let mut srgb = [255u8; 4];
                for &(r, kind) in &roles {
                    match *kind {
                        PropKind::Scalar(ty) => {
                            let x = body
                                .next(ty)
                                .ok_or_else(|| body.describe_failure(&el.name, item, el.count))?;
                            match r {
                                Role::X => v.position[0] = x as f32,
                                Role::Y => v.position[1] = x as f32,
                                Role::Z => v.position[2] = x as f32,
                                Role::Nx => v.normal[0] = x as f32,
                                Role::Ny => v.normal[1] = x as f32,
                                Role::Nz => v.normal[2] = x as f32,
                                Role::R => srgb[0] = color8(ty, x),
                                Role::G => srgb[1] = color8(ty, x),
                                Role::B => srgb[2] = color8(ty, x),
                                Role::A => srgb[3] = color8(ty, x),
                                Role::U => v.uv[0] = x as f32,
                                Role::V => v.uv[1] = x as f32,
                                Role::Other => {}
                            }
                        }
                        PropKind::List { count, item: ity } => {
                            skip_list(&mut body, count, ity)
                                .ok_or_else(|| body.describe_failure(&el.name, item, el.count))?;
                        }
                    }
                }
                v.position = up.to_y_up(v.position);
                v.normal = up.to_y_up(v.normal);
                // PLY texture coordinates have their origin at the bottom left.
                v.uv[1] = 1.0 - v.uv[1];
                v.color = [
                    srgb8_to_linear8(srgb[0]),
                    srgb8_to_linear8(srgb[1]),
                    srgb8_to_linear8(srgb[2]),
                    srgb[3],
                ];
                mesh.vertices.push(v);
            }
        } else if el.name == "face" && !seen_face {
            seen_face = true;
            let Some(list_at) = el.props.iter().position(|p| {
                matches!(p.kind, PropKind::List { .. })
                    && (p.name == "vertex_indices" || p.name == "vertex_index")
            }) else {
                return Err(
                    "element `face` has no list property `vertex_indices` or `vertex_index`".into(),
                );
            };
            mesh.indices.reserve(cap.saturating_mul(3));
            for item in 0..el.count {
                if item % PROGRESS_EVERY == 0 {
                    progress(item, el.count);
                }
                for (pi, p) in el.props.iter().enumerate() {
                    let fail = |b: &Body| b.describe_failure(&el.name, item, el.count);
                    match p.kind {
                        PropKind::Scalar(ty) => {
                            body.next(ty).ok_or_else(|| fail(&body))?;
                        }
                        PropKind::List { count, item: ity } if pi == list_at => {
                            let n = list_len(&mut body, count).ok_or_else(|| fail(&body))?;
                            let mut first = 0;
                            let mut prev = 0;
                            for k in 0..n {
                                let i = index(body.next(ity).ok_or_else(|| fail(&body))?);
                                match k {
                                    0 => first = i,
                                    1 => prev = i,
                                    _ => {
                                        mesh.indices.extend_from_slice(&[first, prev, i]);
                                        prev = i;
                                    }
                                }
                            }
                        }
                        PropKind::List { count, item: ity } => {
                            skip_list(&mut body, count, ity).ok_or_else(|| fail(&body))?;
                        }
                    }
                }
            }
            progress(el.count, el.count);
        } else if !el.props.is_empty() {
            // (an element without properties takes no bytes: nothing to skip, however many
            // items it declares; looping over them was a hang found by fuzzing)
            for item in 0..el.count {
                for p in &el.props {
                    let ok = match p.kind {
                        PropKind::Scalar(ty) => body.next(ty).map(|_| ()),
                        PropKind::List { count, item: ity } => skip_list(&mut body, count, ity),
                    };
                    ok.ok_or_else(|| body.describe_failure(&el.name, item, el.count))?;
                }
            }
        }
    }
    if !seen_vertex {
        return Err("no `vertex` element".into());
    }
    if !seen_face {
        return Err("no `face` element (point clouds are not supported)".into());
    }
    Ok(mesh)
}

/// Reads a list length; `None` if it is missing or not a non-negative integer.
fn list_len(body: &mut Body, count: Ty) -> Option<u64> {
    let n = body.next(count)?;
    (n >= 0.0 && n.fract() == 0.0).then_some(n as u64)
}

fn skip_list(body: &mut Body, count: Ty, item: Ty) -> Option<()> {
    let n = list_len(body, count)?;
    for _ in 0..n {
        body.next(item)?;
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fan_triangulates_and_skips_other_properties() {
        let ply = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nproperty uchar flags\nelement face 1\nproperty uchar flags\n\
property list uchar int vertex_index\nproperty list uchar float texcoord\nend_header\n\
0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n7 4 0 1 2 3 2 0.5 0.5\n";
        let mesh = parse(ply, UpAxis::Y, &mut |_, _| {}).map_err(|e| e.to_string());
        let mesh = mesh.unwrap_or_default();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.indices, vec![0, 1, 2, 0, 2, 3]);
    }

    #[test]
    fn truncation_is_reported() {
        let ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n\
property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
end_header\n\x00\x00";
        let err = parse(ply, UpAxis::Y, &mut |_, _| {})
            .err()
            .unwrap_or_default();
        assert!(err.contains("truncated"), "{err}");
    }

    #[test]
    fn bad_indices_become_out_of_range() {
        assert_eq!(index(-1.0), u32::MAX);
        assert_eq!(index(1.5), u32::MAX);
        assert_eq!(index(7.0), 7);
    }

    #[test]
    fn srgb_conversion_endpoints() {
        assert_eq!(srgb8_to_linear8(0), 0);
        assert_eq!(srgb8_to_linear8(255), 255);
        assert_eq!(srgb8_to_linear8(188), 128);
    }
}
