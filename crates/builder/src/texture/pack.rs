//! The shelf packer: the rectangles of a patch texture (chart crops with their gutters,
//! solid-colour blocks, re-cut charts) placed side by side in one texture.
//!
//! Its own module because both texture paths pack, the source cuts ([`super::Baker`])
//! and the re-cut charts ([`crate::recut`]), and the planner ([`super::plan`]) must pack
//! as they do: it sits below all three, so the texture stage never imports the re-cut.
//! Written here, a few lines: the packing crates on crates.io pack into fixed bins or
//! need the whole set at once with rotation, which would break the affine UV maps.

use tessera_format::{TextureCodec, MAX_TEXTURE_DIM};
use tessera_mesh::NO_TEXTURE;

/// Texels of gutter around every chart rectangle (bilinear filtering reads one texel
/// beyond a chart's edge; mip level 1 of the patch texture reads two).
pub(crate) const GUTTER: i64 = 2;

/// A rectangle of one image's pyramid level that some charts share.
#[derive(Clone, Debug)]
pub(crate) struct Rect {
    /// Texture index (into the sources) or `NO_TEXTURE` for a solid colour.
    pub(crate) texture: u32,
    pub(crate) level: usize,
    /// Texel bounds at `level`, gutter included (may extend beyond the image: wrapped).
    pub(crate) x0: i64,
    pub(crate) y0: i64,
    pub(crate) x1: i64,
    pub(crate) y1: i64,
    /// Solid colour (when `texture == NO_TEXTURE`).
    pub(crate) color: [u8; 4],
    /// Placement in the patch texture.
    pub(crate) dx: i64,
    pub(crate) dy: i64,
}

impl Rect {
    /// A `w` x `h` rectangle of a re-cut chart, to be placed by [`pack`] (of no source
    /// image: only its size and placement are read).
    pub(crate) fn placed(w: i64, h: i64) -> Rect {
        Rect {
            texture: NO_TEXTURE,
            level: 0,
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
            color: [0; 4],
            dx: 0,
            dy: 0,
        }
    }
    pub(crate) fn w(&self) -> i64 {
        self.x1 - self.x0
    }
    pub(crate) fn h(&self) -> i64 {
        self.y1 - self.y0
    }
    /// Whether one rectangle around both holds no more texels than the two apart: two
    /// charts sharing texels are cut once, but two neighbours of an atlas whose gutters
    /// touch are not (merged in a chain, a shelf of small charts would become one
    /// rectangle of mostly the atlas's empty space).
    fn union_pays(&self, o: &Rect) -> bool {
        let w = self.x1.max(o.x1) - self.x0.min(o.x0);
        let h = self.y1.max(o.y1) - self.y0.min(o.y0);
        w * h <= self.w() * self.h() + o.w() * o.h()
    }
    fn overlaps(&self, o: &Rect) -> bool {
        self.texture == o.texture
            && self.level == o.level
            && self.x0 < o.x1
            && o.x0 < self.x1
            && self.y0 < o.y1
            && o.y0 < self.y1
    }
}

/// Merges rectangles of one image level that overlap into their bounding box, until
/// none overlap; `rect_of_chart` follows. Charts that share texels share them once.
pub(crate) fn merge_overlapping(rects: &mut Vec<Rect>, rect_of_chart: &mut [usize]) {
    loop {
        let mut merged_any = false;
        let mut i = 0;
        while i < rects.len() {
            let mut j = i + 1;
            while j < rects.len() {
                if rects[i].overlaps(&rects[j]) && rects[i].union_pays(&rects[j]) {
                    let o = rects.swap_remove(j);
                    let r = &mut rects[i];
                    r.x0 = r.x0.min(o.x0);
                    r.y0 = r.y0.min(o.y0);
                    r.x1 = r.x1.max(o.x1);
                    r.y1 = r.y1.max(o.y1);
                    let moved = rects.len(); // the old index of the rect now at j
                    for c in rect_of_chart.iter_mut() {
                        if *c == j {
                            *c = i;
                        } else if *c == moved {
                            *c = j;
                        }
                    }
                    merged_any = true;
                } else {
                    j += 1;
                }
            }
            i += 1;
        }
        if !merged_any {
            return;
        }
    }
}

/// Shelf packing, tallest first, into a texture about as wide as it is tall. Sets each
/// rectangle's placement; the texture's size, or `None` past [`MAX_TEXTURE_DIM`].
/// With `align` > 1 (4 for BC7) every rectangle takes a cell of whole `align` x `align`
/// blocks at a multiple of `align` ([`cell`]), and the texture's sides are multiples of
/// it: no block holds texels of two rectangles, so a block codec never mixes their
/// colours (the cell's padding repeats the rectangle's last row and column).
pub(crate) fn pack(rects: &mut [Rect], align: i64) -> Option<(i64, i64)> {
    let max = MAX_TEXTURE_DIM as i64;
    let area: i64 = rects
        .iter()
        .map(|r| cell(r.w(), align) * cell(r.h(), align))
        .sum();
    let widest = rects.iter().map(|r| cell(r.w(), align)).max().unwrap_or(1);
    if widest > max || rects.iter().any(|r| cell(r.h(), align) > max) {
        return None;
    }
    let width = cell(
        (((area as f64) * 1.1).sqrt().ceil() as i64).max(widest),
        align,
    )
    .min(max);
    let mut order: Vec<usize> = (0..rects.len()).collect();
    order.sort_by_key(|&i| (-rects[i].h(), -rects[i].w()));
    let (mut x, mut y, mut row_h, mut used_w) = (0i64, 0i64, 0i64, 0i64);
    for i in order {
        let r = &mut rects[i];
        let (w, h) = (cell(r.w(), align), cell(r.h(), align));
        if x + w > width {
            y += row_h;
            x = 0;
            row_h = 0;
        }
        r.dx = x;
        r.dy = y;
        x += w;
        used_w = used_w.max(x);
        row_h = row_h.max(h);
    }
    let height = y + row_h;
    (height <= max).then_some((cell(used_w.max(1), align), cell(height.max(1), align)))
}

/// `n` rounded up to a multiple of `align`.
pub(crate) fn cell(n: i64, align: i64) -> i64 {
    (n + align - 1) / align * align
}

/// The packing alignment of `codec`'s textures: 4 x 4 blocks for BC7, none otherwise.
pub(crate) fn codec_align(codec: TextureCodec) -> i64 {
    match codec {
        TextureCodec::Bc7 => 4,
        TextureCodec::Png | TextureCodec::Jpeg => 1,
    }
}

/// The texel rectangle of a re-cut chart of `extent` at `texel`: its span, one texel
/// for the rounding and a gutter each side.
pub fn chart_cells(extent: [f64; 2], texel: f64) -> [i64; 2] {
    extent.map(|e| {
        let n = (e / texel).ceil();
        let n = if n.is_finite() { n.min(1e6) as i64 } else { 1 };
        n + 1 + 2 * GUTTER
    })
}

/// Texels of the texture of a re-cut patch with charts of `extents` at `texel`, packed
/// as the re-cut baker packs them; `u64::MAX` when they do not fit [`MAX_TEXTURE_DIM`].
pub fn planned_texels(extents: &[[f64; 2]], texel: f64, align: i64) -> u64 {
    let mut rects: Vec<Rect> = extents
        .iter()
        .map(|&e| {
            let [w, h] = chart_cells(e, texel);
            Rect::placed(w, h)
        })
        .collect();
    match pack(&mut rects, align) {
        Some((w, h)) => (w * h) as u64,
        None => u64::MAX,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(texture: u32, x0: i64, y0: i64, x1: i64, y1: i64) -> Rect {
        Rect {
            texture,
            level: 0,
            x0,
            y0,
            x1,
            y1,
            color: [0; 4],
            dx: 0,
            dy: 0,
        }
    }

    #[test]
    fn overlapping_rectangles_merge_and_charts_follow() {
        let mut rects = vec![
            rect(0, 0, 0, 10, 10),
            rect(0, 50, 50, 60, 60),
            rect(0, 2, 2, 12, 12),
            rect(1, 0, 0, 10, 10),
            // Overlaps the first two corners only (gutters touching in an atlas): one
            // rectangle around both would hold more texels than the two apart.
            rect(0, 8, 8, 30, 30),
        ];
        let mut of = vec![0, 1, 2, 3, 4];
        merge_overlapping(&mut rects, &mut of);
        assert_eq!(rects.len(), 4);
        assert_eq!(of[0], of[2]);
        let r = &rects[of[0]];
        assert_eq!((r.x0, r.y0, r.x1, r.y1), (0, 0, 12, 12));
        assert_eq!(rects[of[1]].x0, 50);
        assert_eq!(rects[of[3]].texture, 1);
        let r = &rects[of[4]];
        assert_eq!((r.x0, r.y0, r.x1, r.y1), (8, 8, 30, 30));
    }

    #[test]
    fn packing_places_rectangles_apart_within_the_texture() {
        let mut rects: Vec<Rect> = (0..40)
            .map(|i| rect(0, 0, 0, 3 + i % 7 * 5, 2 + i % 5 * 9))
            .collect();
        let (w, h) = pack(&mut rects, 1).expect("fits");
        for (i, a) in rects.iter().enumerate() {
            assert!(a.dx >= 0 && a.dy >= 0 && a.dx + a.w() <= w && a.dy + a.h() <= h);
            for b in &rects[i + 1..] {
                let apart = a.dx + a.w() <= b.dx
                    || b.dx + b.w() <= a.dx
                    || a.dy + a.h() <= b.dy
                    || b.dy + b.h() <= a.dy;
                assert!(apart, "{a:?} overlaps {b:?}");
            }
        }
        let area: i64 = rects.iter().map(|r| r.w() * r.h()).sum();
        assert!(
            (w * h) as f64 <= 2.0 * area as f64,
            "{w}x{h} for {area} texels"
        );
        assert!(pack(&mut [rect(0, 0, 0, 5000, 4)], 1).is_none());
    }
}
