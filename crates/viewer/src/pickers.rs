//! Full-resolution picks off the frame's thread: a pick reads the leaf patches under
//! the ray from the model (a cold pick reads a few patches from disk or the network),
//! so it runs on a worker and the frame never waits; the answer arrives a frame or two
//! later.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use tessera_format::PatchReader;
use tessera_pick::{Hit, Ray};
use tessera_select::Placement;

/// What a pick is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Purpose {
    /// Double-click: recentre the orbit on the point.
    Recentre,
    /// Measure mode: the next end of the measured segment.
    Measure,
    /// A click with nothing else to do: show the point.
    Inspect,
}

/// A finished pick.
pub struct Picked {
    pub purpose: Purpose,
    /// None: the ray met no surface.
    pub hit: Option<Hit>,
    pub ms: f64,
    /// An error reading the model (the pick found nothing it could trust).
    pub error: Option<String>,
}

/// The worker and its two channels.
pub struct Picker {
    tx: Sender<(Purpose, Ray, Vec<bool>)>,
    rx: Receiver<Picked>,
    pending: usize,
}

impl Picker {
    /// A worker picking on `models`, each where its placement puts it (the nearest hit
    /// over the visible ones; the ray taken into each model's coordinates, the hit
    /// brought back to the world's).
    pub fn new(models: Vec<(Arc<dyn PatchReader>, Placement)>) -> Picker {
        let (tx, jobs) = channel::<(Purpose, Ray, Vec<bool>)>();
        let (done, rx) = channel();
        std::thread::Builder::new()
            .name("tessera-pick".into())
            .spawn(move || {
                for (purpose, ray, visible) in jobs {
                    let t0 = Instant::now();
                    let (mut hit, mut error): (Option<Hit>, Option<String>) = (None, None);
                    for (i, (model, placement)) in models.iter().enumerate() {
                        if !visible.get(i).copied().unwrap_or(true) {
                            continue;
                        }
                        match tessera_pick::pick(model.as_ref(), &ray_to_model(&ray, placement)) {
                            Ok((Some(h), _)) => {
                                let h = hit_to_world(h, placement);
                                if hit.as_ref().is_none_or(|b| h.distance < b.distance) {
                                    hit = Some(h);
                                }
                            }
                            Ok((None, _)) => {}
                            Err(e) => error = Some(e.to_string()),
                        }
                    }
                    // A model that could not be picked matters only if nothing was hit.
                    if hit.is_some() {
                        error = None;
                    }
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    if done
                        .send(Picked {
                            purpose,
                            hit,
                            ms,
                            error,
                        })
                        .is_err()
                    {
                        break;
                    }
                }
            })
            .expect("spawn the pick thread");
        Picker { tx, rx, pending: 0 }
    }

    /// Queues a pick along `ray` over the models marked `visible`.
    pub fn pick(&mut self, purpose: Purpose, ray: Ray, visible: Vec<bool>) {
        if self.tx.send((purpose, ray, visible)).is_ok() {
            self.pending += 1;
        }
    }

    /// Picks finished since the last call.
    pub fn poll(&mut self) -> Vec<Picked> {
        let done: Vec<Picked> = self.rx.try_iter().collect();
        self.pending -= done.len().min(self.pending);
        done
    }

    /// Picks queued and not answered yet.
    pub fn pending(&self) -> usize {
        self.pending
    }
}

/// A world ray in `placement`'s model coordinates (its direction keeps its length in
/// world units per unit of `t`, so distances come back scaled: see [`hit_to_world`]).
fn ray_to_model(ray: &Ray, placement: &Placement) -> Ray {
    if placement.is_identity() {
        return *ray;
    }
    let o = placement.to_model(DVec3::from(ray.origin));
    let d = placement.direction_to_model(DVec3::from(ray.dir));
    Ray::new(o.to_array(), d.to_array())
}

/// A hit in model coordinates brought to the world's.
fn hit_to_world(h: Hit, placement: &Placement) -> Hit {
    if placement.is_identity() {
        return h;
    }
    Hit {
        point: placement.to_world(DVec3::from(h.point)).to_array(),
        distance: h.distance * placement.scale,
        normal: placement
            .direction_to_world(DVec3::from(h.normal))
            .to_array(),
        ..h
    }
}
