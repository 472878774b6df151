//! The plain resampler: visibility-field.txt §4 read pixel by pixel, written to be checked
//! rather than to be fast. The fast resampler (`resample::resample`, by blocks) must give the
//! same marks, the same pixels to the fallback and the same counts
//! (`tests/test_field.py::test_block_resampling_marks_what_the_plain_resampler_marks`).
//!
//! For each resampled pixel, its line is read from each slab in turn. A slab that holds the
//! line reads its samples; a trusted read (under the paper's rule, every read) marks the cells
//! they hold and answers the pixel. A line that sees nothing inside the bounds is answered
//! without marks. Under conservative resampling a pixel, once answered, is not read from the
//! later slabs; under the paper's rule every slab adds its marks. A pixel no slab answered goes
//! to the fallback: overflowed when some slab held its line, outside when none did.

use super::build::Slab;
use super::lines::{Answer, Lines, Marks, Resampling, Samples, SlabRead};
use crate::camera::Camera;
use crate::error::Result;

/// [`resample`](super::resample::resample)'s marks, one pixel at a time.
pub fn resample(
    fields: &[(Slab, Samples)],
    cell_count: usize,
    camera: &Camera,
    how: Resampling,
) -> Result<Marks> {
    let lines = Lines::new(fields, camera, how)?;
    let mut bits = Vec::new();
    let mut missed = Vec::new();
    for r in 0..lines.rows {
        for c in 0..lines.cols {
            if let Some(why) = read_pixel(&lines, c, r, &mut bits) {
                missed.push((lines.flat(c, r), why));
            }
        }
    }
    lines.finish(cell_count, &bits, missed)
}

/// Read resampled pixel (c, r)'s line from the slabs, setting the bits of the samples its
/// trusted reads take; why it was not answered, if it was not.
fn read_pixel(lines: &Lines, c: usize, r: usize, bits: &mut Vec<u64>) -> Option<Answer> {
    let conservative = lines.how.conservative.is_some();
    let line = lines.line(c, r);
    let seen = lines.seen(line);
    let (mut answered, mut held) = (false, false);
    for slab in 0..lines.fields.len() {
        if answered && conservative {
            break;
        }
        match lines.read(slab, line, seen) {
            SlabRead::No => {}
            SlabRead::Nothing => answered = true,
            SlabRead::Reads { first, two } => {
                held = true;
                if lines.trusted(slab, first, two) {
                    lines.set_read(bits, slab, first, two);
                    answered = true;
                }
            }
        }
    }
    match (answered, held) {
        (true, _) => None,
        (false, true) => Some(Answer::Overflowed),
        (false, false) => Some(Answer::Outside),
    }
}
