//! The font of every PNG plot, embedded in the binary: DejaVu Sans 2.37 (Bitstream Vera
//! licence, `lab/assets/fonts/LICENSE`), registered with plotters as its `sans-serif` family —
//! the family of every caption and axis label — so that text renders with no system font
//! library (fontconfig, freetype) and no installed font.

use plotters::style::FontStyle;
use std::sync::Once;

/// DejaVu Sans, TrueType.
static DEJAVU_SANS: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Register the embedded font as `sans-serif` (normal style), once per process; every function
/// that draws a PNG calls this first.
pub fn register() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, DEJAVU_SANS)
            .unwrap_or_else(|_| unreachable!("the embedded DejaVu Sans is a valid TrueType font"));
    });
}

#[cfg(test)]
mod tests {
    use plotters::prelude::*;

    #[test]
    fn text_renders_with_the_embedded_font() {
        super::register();
        let (w, h) = (200u32, 60u32);
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.draw(&Text::new("Sextant 42", (10, 15), ("sans-serif", 24)))
                .unwrap();
            root.present().unwrap();
        }
        let inked = buf.chunks(3).filter(|p| p[0] < 128).count();
        // Ten glyphs at 24 px cover a few hundred pixels; an empty or missing font none.
        assert!(inked > 200, "{inked} dark pixels");
    }
}
