//! The decode gate: decoding a source image is what the texture stage needs memory for
//! (the decoder's output, its RGBA8 copy and the next pyramid level), so the decodes in
//! flight at once are bounded by the stage's budget, and an image no budget could
//! decode is refused before any work.

use std::sync::{Condvar, Mutex};

use tessera_mesh::TextureSource;

/// Decoded bytes per texel a decode holds at once (estimate for the decode gate): the
/// decoder's output (up to 3 bytes a texel for JPEG, 4 for 8-bit PNG), its RGBA8 copy
/// (4) and the next pyramid level (1).
pub(crate) const DECODE_BYTES_PER_TEXEL: u64 = 8;

/// Limits the decoded bytes of the images being decoded at once to a budget (one image
/// larger than the budget decodes alone). Holders wait for nothing else, so it cannot
/// deadlock.
pub(crate) struct DecodeGate {
    pub(crate) budget: u64,
    in_flight: Mutex<u64>,
    freed: Condvar,
}

impl DecodeGate {
    /// A gate admitting decodes of `budget` bytes together.
    pub(crate) fn new(budget: u64) -> DecodeGate {
        DecodeGate {
            budget,
            in_flight: Mutex::new(0),
            freed: Condvar::new(),
        }
    }

    /// Waits until a decode of `bytes` fits beside those in flight (or none is), and
    /// holds its place until the ticket drops.
    pub(crate) fn enter(&self, bytes: u64) -> DecodeTicket<'_> {
        let mut held = self.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        while *held > 0 && *held + bytes > self.budget {
            held = self.freed.wait(held).unwrap_or_else(|e| e.into_inner());
        }
        *held += bytes;
        DecodeTicket { gate: self, bytes }
    }
}

pub(crate) struct DecodeTicket<'a> {
    gate: &'a DecodeGate,
    bytes: u64,
}

impl Drop for DecodeTicket<'_> {
    fn drop(&mut self) {
        let mut held = self
            .gate
            .in_flight
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        *held -= self.bytes;
        self.gate.freed.notify_all();
    }
}

/// Refuses, before any work, a texture image whose decode needs more memory than
/// `memory_bytes` (`--memory`) allows: about [`DECODE_BYTES_PER_TEXEL`] bytes a texel
/// (its size is read from its header at import). A small PNG may claim 11000 x 11000
/// texels (968 MB to decode); an image larger than the stage's share of the budget
/// decodes alone, so the whole budget is the bound. The error is the message.
pub fn check_decode_memory(sources: &[TextureSource], memory_bytes: u64) -> Result<(), String> {
    for src in sources {
        let [w, h] = src.size;
        let need = u64::from(w) * u64::from(h) * DECODE_BYTES_PER_TEXEL;
        if need > memory_bytes {
            return Err(format!(
                "texture image '{}' is {w} x {h} texels: decoding it needs about {} MiB \
                 ({DECODE_BYTES_PER_TEXEL} bytes a texel), more than --memory {} MiB allows; \
                 raise --memory to at least {} MiB, or build with --ignore-textures",
                src.image_name,
                need >> 20,
                memory_bytes >> 20,
                need.div_ceil(1 << 20)
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::Ordering;
    use tessera_mesh::{ImageSource, Wrap};

    #[test]
    fn images_too_large_for_the_memory_budget_are_refused() {
        // Why: issue 29, item 8: 11000 x 11000 texels cost 575 MB whatever --memory.
        let t = |w, h| TextureSource {
            material: "m".into(),
            image: ImageSource::File("big.png".into()),
            image_name: "big.png".into(),
            tint: [255; 4],
            wrap: [Wrap::Repeat; 2],
            v_up: true,
            size: [w, h],
        };
        let e = check_decode_memory(&[t(11000, 11000)], 256 << 20).unwrap_err();
        assert!(e.contains("more than --memory 256 MiB"), "{e}");
        check_decode_memory(&[t(4096, 4096)], 256 << 20).unwrap();
    }

    #[test]
    fn the_decode_gate_admits_what_fits_and_one_oversized_alone() {
        // Why: concurrent decodes are the texture stage's memory; the gate must bound
        // them without ever refusing an image larger than the whole budget.
        let gate = DecodeGate::new(100);
        let a = gate.enter(60);
        let b = gate.enter(40);
        assert_eq!(*gate.in_flight.lock().unwrap(), 100);
        drop((a, b));
        let big = gate.enter(500);
        assert_eq!(*gate.in_flight.lock().unwrap(), 500);
        let waited = std::sync::atomic::AtomicBool::new(false);
        std::thread::scope(|s| {
            s.spawn(|| {
                let _t = gate.enter(10);
                assert!(
                    waited.load(Ordering::SeqCst),
                    "entered beside an oversized decode"
                );
            });
            std::thread::sleep(std::time::Duration::from_millis(50));
            waited.store(true, Ordering::SeqCst);
            drop(big);
        });
        assert_eq!(*gate.in_flight.lock().unwrap(), 0);
    }
}
