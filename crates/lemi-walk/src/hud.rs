//! The viewer's on-screen text: lines drawn into the frame's RGBA before it is presented, over a
//! translucent box in the top-left corner, plus a row of colour swatches (the layer legend).
//! Glyphs are rasterized with `ab_glyph` from the font [`crate::font::find_font`] finds for the
//! HUD (DejaVu Sans Mono and other common ones; `LEMI_HUD_FONT` names another file) and cached
//! per character. Without a font the HUD has no text (the viewer's window title carries the
//! numbers).

use std::collections::HashMap;
use std::path::Path;

use crate::font::{find_font, FontUse, LoadedFont};
use ab_glyph::{Font, PxScale, ScaleFont};

/// One rasterized glyph: coverage `w × h` at offset `(dx, dy)` from the pen position on the
/// baseline, and the advance.
struct Glyph {
    w: usize,
    h: usize,
    dx: i32,
    dy: i32,
    advance: f32,
    coverage: Vec<u8>,
}

/// A line of HUD text and its colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    pub text: String,
    pub color: [u8; 3],
}

impl Line {
    pub fn new(text: impl Into<String>) -> Line {
        Line {
            text: text.into(),
            color: [235, 235, 235],
        }
    }

    pub fn colored(text: impl Into<String>, color: [u8; 3]) -> Line {
        Line {
            text: text.into(),
            color,
        }
    }
}

/// The HUD renderer: a font (if one was found) and its glyph cache at one pixel size.
pub struct Hud {
    font: Option<LoadedFont>,
    px: f32,
    glyphs: HashMap<char, Glyph>,
}

impl Default for Hud {
    fn default() -> Hud {
        Hud::new()
    }
}

impl Hud {
    /// Finds a font: `LEMI_HUD_FONT`, then common monospaced and sans fonts.
    pub fn new() -> Hud {
        Hud {
            font: find_font(FontUse::Hud),
            px: 0.0,
            glyphs: HashMap::new(),
        }
    }

    /// The font file used, if any.
    pub fn font_path(&self) -> Option<&Path> {
        self.font.as_ref().map(|f| f.path.as_path())
    }

    fn glyph(&mut self, c: char) -> Option<&Glyph> {
        let font = &self.font.as_ref()?.font;
        let px = self.px;
        Some(self.glyphs.entry(c).or_insert_with(|| {
            let sf = font.as_scaled(PxScale::from(px));
            let id = font.glyph_id(c);
            let advance = sf.h_advance(id);
            let glyph = id.with_scale_and_position(sf.scale(), ab_glyph::point(0.0, 0.0));
            match font.outline_glyph(glyph) {
                Some(o) => {
                    let b = o.px_bounds();
                    let (w, h) = (b.width().ceil() as usize, b.height().ceil() as usize);
                    let mut coverage = vec![0u8; w * h];
                    o.draw(|x, y, v| {
                        if let Some(c) = coverage.get_mut(y as usize * w + x as usize) {
                            *c = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                        }
                    });
                    Glyph {
                        w,
                        h,
                        dx: b.min.x.floor() as i32,
                        dy: b.min.y.floor() as i32,
                        advance,
                        coverage,
                    }
                }
                None => Glyph {
                    w: 0,
                    h: 0,
                    dx: 0,
                    dy: 0,
                    advance,
                    coverage: Vec::new(),
                },
            }
        }))
    }

    /// Draws `lines` (and, below them, `swatches`: colour squares labelled with their index)
    /// into `rgba` (`width × height` RGBA8, sRGB), at a text size that suits the image height.
    pub fn draw(
        &mut self,
        rgba: &mut [u8],
        width: u32,
        height: u32,
        lines: &[Line],
        swatches: &[[u8; 3]],
    ) {
        let (w, h) = (width as usize, height as usize);
        if rgba.len() != 4 * w * h || self.font.is_none() {
            return;
        }
        let px = (height as f32 / 36.0).clamp(10.0, 22.0).round();
        if px != self.px {
            self.px = px;
            self.glyphs.clear();
        }
        let line_h = (px * 1.25).ceil() as usize;
        let pad = (px * 0.4).ceil() as usize;
        // box size: the widest line
        let mut box_w = 0.0f32;
        for l in lines {
            let mut x = 0.0;
            for c in l.text.chars() {
                x += self.glyph(c).map_or(0.0, |g| g.advance);
            }
            box_w = box_w.max(x);
        }
        let swatch = line_h;
        let swatch_row = if swatches.is_empty() { 0 } else { line_h + pad };
        box_w = box_w.max((swatches.len() * (swatch + pad / 2)) as f32);
        let bw = (box_w.ceil() as usize + 2 * pad).min(w);
        let bh = (lines.len() * line_h + swatch_row + 2 * pad).min(h);
        for y in 0..bh {
            for x in 0..bw {
                let i = 4 * (y * w + x);
                for c in &mut rgba[i..i + 3] {
                    *c = (*c as u16 * 2 / 5) as u8;
                }
            }
        }
        let ascent = self
            .font
            .as_ref()
            .map_or(px * 0.8, |f| f.font.as_scaled(PxScale::from(px)).ascent());
        for (row, l) in lines.iter().enumerate() {
            let baseline = (pad + row * line_h) as f32 + ascent;
            let mut pen = pad as f32;
            for c in l.text.chars() {
                let Some(g) = self.glyph(c) else { break };
                let gx = pen.round() as i32 + g.dx;
                let gy = baseline.round() as i32 + g.dy;
                for yy in 0..g.h {
                    for xx in 0..g.w {
                        let (x, y) = (gx + xx as i32, gy + yy as i32);
                        if x < 0 || y < 0 || x as usize >= w || y as usize >= h {
                            continue;
                        }
                        let a = g.coverage[yy * g.w + xx] as u32;
                        if a == 0 {
                            continue;
                        }
                        let i = 4 * (y as usize * w + x as usize);
                        for k in 0..3 {
                            let dst = rgba[i + k] as u32;
                            rgba[i + k] = ((l.color[k] as u32 * a + dst * (255 - a)) / 255) as u8;
                        }
                    }
                }
                pen += g.advance;
            }
        }
        if !swatches.is_empty() {
            let y0 = pad + lines.len() * line_h + pad / 2;
            for (k, col) in swatches.iter().enumerate() {
                let x0 = pad + k * (swatch + pad / 2);
                for y in y0..(y0 + swatch).min(h) {
                    for x in x0..(x0 + swatch).min(w) {
                        let i = 4 * (y * w + x);
                        rgba[i..i + 3].copy_from_slice(col);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_darkens_the_box_and_draws_light_glyphs() {
        let mut hud = Hud::new();
        let (w, h) = (320u32, 180u32);
        let mut img = vec![128u8; (4 * w * h) as usize];
        hud.draw(
            &mut img,
            w,
            h,
            &[Line::new("12.3 fps"), Line::new("cell 1_0_0")],
            &[[255, 0, 0], [0, 255, 0]],
        );
        if hud.font_path().is_none() {
            eprintln!("skipped: no system font found (install fonts-dejavu-core)");
            return;
        }
        let px = |x: u32, y: u32| img[(4 * (y * w + x)) as usize];
        let text_pixels = (0..60)
            .flat_map(|y| (0..120).map(move |x| (x, y)))
            .filter(|&(x, y)| px(x, y) > 200)
            .count();
        assert!(text_pixels > 20, "{text_pixels} light text pixels");
        assert!(px(1, 1) < 128, "the box is darkened");
        assert_eq!(px(w - 1, h - 1), 128, "outside the box untouched");
        // a wrong-sized image is left alone
        let mut small = vec![7u8; 12];
        hud.draw(&mut small, w, h, &[Line::new("x")], &[]);
        assert!(small.iter().all(|&v| v == 7));
    }
}
