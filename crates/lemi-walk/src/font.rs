//! The one place that finds a font for text drawn into images: the walk plot's labels
//! ([`crate::plot`]) and the interactive viewer's HUD. Fonts are looked up with `fontdb` among the
//! system's fonts (the usual font folders and those fontconfig's configuration names), by family
//! name in order of preference, then by generic family, then any face; an environment variable
//! names a font file to use instead (`LEMI_PLOT_FONT`, `LEMI_HUD_FONT`). Glyphs are rasterized
//! with `ab_glyph` by the callers.

use std::path::PathBuf;

use ab_glyph::FontVec;
use fontdb::{Database, Family, Query, Source};

/// What the text is for: which families are preferred and which variable overrides them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FontUse {
    /// Plot labels: a proportional sans-serif face; `LEMI_PLOT_FONT` names another file.
    Plot,
    /// The viewer's HUD: a monospaced face first (columns of numbers stay put), else a sans-serif
    /// one; `LEMI_HUD_FONT` names another file.
    Hud,
}

const SANS: [&str; 6] = [
    "DejaVu Sans",
    "Liberation Sans",
    "FreeSans",
    "Noto Sans",
    "Arial",
    "Helvetica",
];
const MONO: [&str; 5] = [
    "DejaVu Sans Mono",
    "Liberation Mono",
    "Noto Sans Mono",
    "Menlo",
    "Consolas",
];

impl FontUse {
    /// The environment variable that names a font file for this use.
    pub fn env_var(self) -> &'static str {
        match self {
            FontUse::Plot => "LEMI_PLOT_FONT",
            FontUse::Hud => "LEMI_HUD_FONT",
        }
    }

    fn families(self) -> Vec<&'static str> {
        match self {
            FontUse::Plot => SANS.to_vec(),
            FontUse::Hud => MONO.iter().chain(&SANS).copied().collect(),
        }
    }
}

/// A font ready for `ab_glyph`, and where it came from.
pub struct LoadedFont {
    /// The font file (for a face from memory, `<memory>`).
    pub path: PathBuf,
    pub font: FontVec,
}

/// The font for `use_`: the file the use's environment variable names (if it loads), else the
/// first system face of the preferred families, else of the generic family, else any face that
/// loads. `None`: no usable font on this system (callers then draw no text).
pub fn find_font(use_: FontUse) -> Option<LoadedFont> {
    if let Some(p) = std::env::var_os(use_.env_var()) {
        let path = PathBuf::from(p);
        if let Some(font) = std::fs::read(&path)
            .ok()
            .and_then(|b| FontVec::try_from_vec(b).ok())
        {
            return Some(LoadedFont { path, font });
        }
    }
    let mut db = Database::new();
    db.load_system_fonts();
    let load = |id: fontdb::ID| -> Option<LoadedFont> {
        let face = db.face(id)?;
        let path = match &face.source {
            Source::File(p) | Source::SharedFile(p, _) => p.clone(),
            Source::Binary(_) => PathBuf::from("<memory>"),
        };
        let font = db.with_face_data(id, |data, index| {
            FontVec::try_from_vec_and_index(data.to_vec(), index).ok()
        })??;
        Some(LoadedFont { path, font })
    };
    let query = |families: &[Family]| {
        db.query(&Query {
            families,
            ..Query::default()
        })
    };
    for name in use_.families() {
        if let Some(f) = query(&[Family::Name(name)]).and_then(load) {
            return Some(f);
        }
    }
    let generic = match use_ {
        FontUse::Plot => Family::SansSerif,
        FontUse::Hud => Family::Monospace,
    };
    if let Some(f) = query(&[generic]).and_then(load) {
        return Some(f);
    }
    // Any face, monospaced ones first for the HUD; in a stable order (by path).
    let mut faces: Vec<(bool, PathBuf, fontdb::ID)> = db
        .faces()
        .map(|f| {
            let path = match &f.source {
                Source::File(p) | Source::SharedFile(p, _) => p.clone(),
                Source::Binary(_) => PathBuf::new(),
            };
            (!(use_ == FontUse::Hud && f.monospaced), path, f.id)
        })
        .collect();
    faces.sort();
    faces.into_iter().find_map(|(_, _, id)| load(id))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finding_a_font_never_panics() {
        // Whatever the system has, looking never panics; a found font has glyphs.
        for u in [FontUse::Plot, FontUse::Hud] {
            if let Some(f) = find_font(u) {
                use ab_glyph::Font;
                assert!(f.font.glyph_count() > 0, "{}", f.path.display());
                eprintln!("{u:?}: {}", f.path.display());
            }
        }
        assert_eq!(FontUse::Hud.env_var(), "LEMI_HUD_FONT");
        assert_eq!(FontUse::Plot.families()[0], "DejaVu Sans");
        assert_eq!(FontUse::Hud.families()[0], "DejaVu Sans Mono");
    }
}
