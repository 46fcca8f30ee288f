//! Several models in one scene (real pixels on lavapipe): two noisy spheres built from
//! generated PLY files, B shifted by +4 along x, drawn in their model coordinates with
//! one GPU budget and one RAM budget shared by demand.

use std::path::Path;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use glam::{DQuat, DVec3};
use tessera_build::{BuildOptions, NoProgress};
use tessera_format::{Model, PatchReader};
use tessera_mesh::{PlyWriter, PlyWriterOptions};
use tessera_render::{
    diff_stats, enclosed_background_pixels, FrameStats, Gpu, Image, Mode, Viewer, ViewerOptions,
};
use tessera_select::{Camera, Placement};

const MAGENTA: [f64; 4] = [1.0, 0.0, 1.0, 1.0];
const BG: [u8; 3] = [255, 0, 255];
/// Where B's centre is (A's is the origin).
const B_OFFSET: [f32; 3] = [4.0, 0.0, 0.0];
const W: u32 = 320;
const H: u32 = 240;

/// A whole mesh in memory (the test spheres are small).
type Mesh = tessera_testkit::MeshCollector;

/// Writes a copy of the PLY `from` with every position moved by `offset`.
fn shifted_copy(from: &Path, to: &Path, offset: [f32; 3]) {
    let mut m = Mesh::default();
    tessera_mesh::read_mesh(from, &mut m).expect("read PLY");
    let mut w = PlyWriter::create(
        to,
        &PlyWriterOptions {
            attributes: m.header.attributes,
            vertex_count: m.vertices.len() as u64,
            face_count: m.triangles.len() as u64,
            comments: vec!["shifted test sphere".into()],
        },
    )
    .expect("create PLY");
    for v in &m.vertices {
        let mut v = *v;
        for (p, o) in v.position.iter_mut().zip(offset) {
            *p += o;
        }
        w.write_vertex(&v).expect("vertex");
    }
    for t in &m.triangles {
        w.write_triangle(*t).expect("triangle");
    }
    w.finish().expect("finish PLY");
}

struct Pair {
    _dir: tempfile::TempDir,
    a: Arc<Model>,
    b: Arc<Model>,
}

/// The two models, built once for all tests of this file.
fn pair() -> &'static Pair {
    static P: OnceLock<Pair> = OnceLock::new();
    P.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let opts = BuildOptions {
            memory_bytes: 256 << 20,
            threads: Some(2),
            leaf_triangles: 400,
            node_triangles: 200,
            ..BuildOptions::default()
        };
        let mut models = Vec::new();
        for (name, seed, offset) in [("a", 7, [0.0; 3]), ("b", 11, B_OFFSET)] {
            let ply = dir.path().join(format!("{name}.ply"));
            tessera_gen::write_sphere(
                &ply,
                &tessera_gen::SphereOptions {
                    triangles: 60_000,
                    seed,
                    colors: false,
                    noise: 0.05,
                },
                &tessera_gen::NoProgress,
            )
            .expect("generate sphere");
            let input = if offset == [0.0; 3] {
                ply
            } else {
                let moved = dir.path().join(format!("{name}_moved.ply"));
                shifted_copy(&ply, &moved, offset);
                moved
            };
            let tsr = dir.path().join(format!("{name}.tsr"));
            tessera_build::build(&input, &tsr, &opts, &NoProgress).expect("build");
            models.push(Arc::new(Model::open(&tsr).expect("open")));
        }
        let b = models.pop().expect("b");
        let a = models.pop().expect("a");
        Pair { _dir: dir, a, b }
    })
}

fn reader(m: &Arc<Model>) -> Arc<dyn PatchReader> {
    m.clone()
}

fn camera(position: [f64; 3], target: [f64; 3]) -> Camera {
    Camera {
        position,
        target,
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 50.0,
        width: W,
        height: H,
    }
}

/// Both spheres side by side, apart on screen.
fn both_camera() -> Camera {
    camera([2.0, 0.0, 7.0], [2.0, 0.0, 0.0])
}

/// A close-up of A (B outside the frustum), and of B (A outside).
fn a_camera() -> Camera {
    camera([0.0, 0.0, 2.2], [0.0, 0.0, 0.0])
}
fn b_camera() -> Camera {
    camera([4.0, 0.0, 2.2], [4.0, 0.0, 0.0])
}

fn opts(mode: Mode, tolerance_px: f32, gpu_budget_bytes: u64) -> ViewerOptions {
    ViewerOptions {
        mode,
        tolerance_px,
        gpu_budget_bytes,
        background: MAGENTA,
        ..Default::default()
    }
}

fn gpu() -> Gpu {
    Gpu::headless().expect("a GPU adapter (is lavapipe installed? mesa-vulkan-drivers)")
}

fn covered(img: &Image, x: usize) -> bool {
    img.rgba[x * 4..x * 4 + 3] != BG
}

fn pixel(img: &Image, x: usize) -> &[u8] {
    &img.rgba[x * 4..x * 4 + 4]
}

fn differs(p: &[u8], q: &[u8]) -> bool {
    p.iter().zip(q).any(|(a, b)| a.abs_diff(*b) > 16)
}

/// Frames until the view has settled: at least `min_s` seconds, then nothing pending
/// and the same triangles and per-model bytes for 5 frames (at most `max_s`). With
/// `TESSERA_TEST_TRACE` set, every frame is printed.
fn settle(v: &mut Viewer, cam: &Camera, min_s: f64, max_s: f64) -> FrameStats {
    let t = Instant::now();
    let mut same = 0;
    let mut prev: Option<(u64, Vec<u64>)> = None;
    loop {
        let s = v.render(cam).expect("render");
        let key = (
            s.triangles,
            (0..v.model_count())
                .map(|i| v.model_stats(i).gpu_resident_bytes)
                .collect::<Vec<_>>(),
        );
        same = if prev.as_ref() == Some(&key) && s.pending_loads == 0 && s.morph_blending == 0 {
            same + 1
        } else {
            0
        };
        if std::env::var_os("TESSERA_TEST_TRACE").is_some() {
            eprintln!(
                "{:.2}s {key:?} pending {} up {} budgets {:?}",
                t.elapsed().as_secs_f64(),
                s.pending_loads,
                s.bytes_uploaded,
                (0..v.model_count())
                    .map(|i| v.model_stats(i).gpu_budget_bytes)
                    .collect::<Vec<_>>()
            );
        }
        prev = Some(key);
        let el = t.elapsed().as_secs_f64();
        if (el >= min_s && same >= 5) || el >= max_s {
            return s;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The two models in one frame match each rendered alone: where only one covers a
/// pixel it is that model's pixel, where both do the nearer one's (A's from this side),
/// and nothing else is drawn. A point picked on each lies on that sphere.
#[test]
fn two_models_appear_at_their_coordinates_with_shared_depth() {
    let p = pair();
    let (ha, hb) = (p.a.header(), p.b.header());
    assert!(
        (hb.bounding_sphere[0] - ha.bounding_sphere[0] - 4.0).abs() < 0.1,
        "B is 4 units right of A: {:?} {:?}",
        ha.bounding_sphere,
        hb.bounding_sphere
    );
    assert_ne!(ha.cube_origin, hb.cube_origin, "each has its own cube");
    let alone = |m: &Arc<Model>, cam: &Camera| {
        let mut v = Viewer::with_gpu(gpu(), reader(m), opts(Mode::Complete, 1.0, 256 << 20))
            .expect("viewer");
        v.render(cam).expect("render");
        v.read_image().expect("read")
    };
    let sides = both_camera();
    // From the left and above: A is nearer and hides part of B.
    let occluding = camera([-5.0, 0.0, 3.0], [2.0, 0.0, 0.0]);
    for mode in [Mode::Complete, Mode::Progressive] {
        let mut v = Viewer::with_models(
            gpu(),
            vec![reader(&p.a), reader(&p.b)],
            opts(mode, 1.0, 256 << 20),
        )
        .expect("scene");
        assert_eq!(v.model_count(), 2);
        for (name, cam) in [("side by side", &sides), ("occluding", &occluding)] {
            let (a, b) = (alone(&p.a, cam), alone(&p.b, cam));
            let s = if mode == Mode::Progressive {
                settle(&mut v, cam, 0.0, 20.0)
            } else {
                v.render(cam).expect("render")
            };
            let img = v.read_image().expect("read");
            let (sa, sb) = (v.model_stats(0).clone(), v.model_stats(1).clone());
            assert_eq!(s.triangles, sa.triangles + sb.triangles);
            assert!(sa.triangles > 0 && sb.triangles > 0, "{sa:?} {sb:?}");
            let (mut only_a, mut only_b, mut both, mut bad) = (0, 0, 0, 0);
            for x in 0..(W * H) as usize {
                let want = match (covered(&a, x), covered(&b, x)) {
                    (true, false) => {
                        only_a += 1;
                        pixel(&a, x)
                    }
                    (false, true) => {
                        only_b += 1;
                        pixel(&b, x)
                    }
                    (true, true) => {
                        both += 1;
                        pixel(&a, x)
                    }
                    (false, false) => &[255, 0, 255, 255][..],
                };
                if differs(pixel(&img, x), want) {
                    bad += 1;
                }
            }
            eprintln!(
                "{mode:?} {name}: A only {only_a}, B only {only_b}, both {both} px, \
                 {bad} px differ; triangles A {} B {}, planes {:?}",
                sa.triangles,
                sb.triangles,
                v.clip_planes()
            );
            if std::env::var_os("TESSERA_TEST_TRACE").is_some() {
                let t = std::env::temp_dir();
                let tag = format!("{mode:?}_{}", name.replace(' ', "_"));
                img.save_png(&t.join(format!("scene_{tag}.png"))).unwrap();
                a.save_png(&t.join(format!("alone_a_{tag}.png"))).unwrap();
                b.save_png(&t.join(format!("alone_b_{tag}.png"))).unwrap();
            }
            assert!(only_a > 2000 && only_b > 1000, "both models on screen");
            if name == "occluding" {
                assert!(both > 200, "B partly behind A: {both} px");
            } else {
                assert_eq!(both, 0);
            }
            // Edges may round differently where the two frames' depth ranges differ.
            assert!(
                bad <= (only_a + only_b + both) / 200,
                "{mode:?} {name}: {bad} pixels differ from the models drawn alone"
            );
        }
        // Pick on each sphere (side by side): the depth buffer is the scene's.
        v.render(&sides).expect("render");
        let proj = |c: [f64; 3]| {
            // Pixel of a model-space point seen from `sides` (looking down -z).
            let cam = &sides;
            let (dx, dy, dz) = (
                c[0] - cam.position[0],
                c[1] - cam.position[1],
                cam.position[2] - c[2],
            );
            let t = (0.5 * cam.fov_y_deg.to_radians()).tan();
            let x = (dx / dz / (t * W as f64 / H as f64) + 1.0) * 0.5 * W as f64;
            let y = (1.0 - dy / dz / t) * 0.5 * H as f64;
            (x, y)
        };
        for (centre, name) in [([0.0, 0.0, 0.0], "A"), ([4.0, 0.0, 0.0], "B")] {
            let (x, y) = proj(centre);
            let hit = v.point_at(x, y).expect("depth").expect("a surface");
            let d = ((hit[0] - centre[0]).powi(2)
                + (hit[1] - centre[1]).powi(2)
                + (hit[2] - centre[2]).powi(2))
            .sqrt();
            assert!(
                (0.9..1.1).contains(&d) && hit[2] > 0.5,
                "{mode:?}: the point picked on {name} ({hit:?}) lies on its front, \
                 {d:.3} from its centre"
            );
        }
    }
}

/// With a GPU budget below the two fine cuts, the model on screen gets the memory:
/// looking at A (B outside the frustum), A refines almost as far as alone with an
/// unlimited budget and B keeps only its pinned roots; turned to B, the reverse.
#[test]
fn shared_budget_goes_to_the_model_on_screen() {
    let p = pair();
    // Each model alone with the default (ample) budget, settled: its demand and cut.
    let mut reference = Vec::new();
    for (m, cam) in [(&p.a, a_camera()), (&p.b, b_camera())] {
        let mut v = Viewer::with_gpu(gpu(), reader(m), opts(Mode::Progressive, 0.5, 256 << 20))
            .expect("viewer");
        let s = settle(&mut v, &cam, 0.0, 20.0);
        let pinned = v.scheduler().pinned_bytes();
        eprintln!(
            "alone: {} triangles, level {}, {} B resident, {} B wanted, roots {} B",
            s.triangles, s.max_level, s.gpu_resident_bytes, s.wanted_bytes, pinned
        );
        assert!(s.wanted_bytes >= s.gpu_resident_bytes * 9 / 10);
        reference.push((s, pinned));
    }
    let (ra, pa) = (&reference[0].0, reference[0].1);
    let (rb, pb) = (&reference[1].0, reference[1].1);
    // Room for both roots and 85% of the larger fine cut beyond them: either model
    // can almost refine fully, never both.
    let fine = (ra.wanted_bytes - pa).max(rb.wanted_bytes - pb);
    let budget = pa + pb + fine * 85 / 100;
    let mut v = Viewer::with_models(
        gpu(),
        vec![reader(&p.a), reader(&p.b)],
        opts(Mode::Progressive, 0.5, budget),
    )
    .expect("scene");
    assert_eq!(v.scheduler_of(0).pinned_bytes(), pa);
    assert_eq!(v.scheduler_of(1).pinned_bytes(), pb);
    for (turn, cam, on, off, alone) in [(1, a_camera(), 0, 1, ra), (2, b_camera(), 1, 0, rb)] {
        // Long enough for the demand of the model that left the screen to decay.
        let s = settle(&mut v, &cam, 2.0, 30.0);
        let (son, soff) = (v.model_stats(on).clone(), v.model_stats(off).clone());
        eprintln!(
            "turn {turn} (budget {budget} B): on screen {} triangles (alone {}), level {} \
             (alone {}), {} B of budget {} ({} B wanted, {} blending); off screen {} B \
             (roots {} B), budget {}",
            son.triangles,
            alone.triangles,
            son.max_level,
            alone.max_level,
            son.gpu_resident_bytes,
            son.gpu_budget_bytes,
            son.wanted_bytes,
            son.morph_blending,
            soff.gpu_resident_bytes,
            v.scheduler_of(off).pinned_bytes(),
            soff.gpu_budget_bytes,
        );
        assert!(s.gpu_resident_bytes <= budget, "{s:?}");
        assert_eq!(soff.triangles, 0, "the model off screen draws nothing");
        assert_eq!(
            soff.gpu_resident_bytes,
            v.scheduler_of(off).pinned_bytes(),
            "turn {turn}: the model off screen is evicted down to its roots"
        );
        assert!(
            son.triangles * 10 >= alone.triangles * 7 && son.max_level + 1 >= alone.max_level,
            "turn {turn}: the model on screen refines nearly as far as alone: {son:?} vs {alone:?}"
        );
        assert!(
            son.gpu_resident_bytes * 10 >= (budget - soff.gpu_resident_bytes) * 7,
            "turn {turn}: the model on screen uses most of the budget"
        );
    }
}

/// A hidden model draws nothing, asks for nothing and gives its memory to the other;
/// shown again, it comes back.
#[test]
fn hiding_a_model_releases_its_pixels_and_memory() {
    let p = pair();
    let cam = both_camera();
    let mut v = Viewer::with_models(
        gpu(),
        vec![reader(&p.a), reader(&p.b)],
        opts(Mode::Progressive, 0.2, 320 << 10),
    )
    .expect("scene");
    let before = settle(&mut v, &cam, 1.0, 20.0);
    let img_both = v.read_image().expect("read");
    let (a0, b0) = (v.model_stats(0).clone(), v.model_stats(1).clone());
    assert!(a0.triangles > 0 && b0.triangles > 0);
    v.set_visible(1, false);
    assert!(!v.is_visible(1) && v.is_visible(0));
    let hidden = settle(&mut v, &cam, 2.0, 30.0);
    let img = v.read_image().expect("read");
    let (a1, b1) = (v.model_stats(0).clone(), v.model_stats(1).clone());
    eprintln!(
        "both: A {} tris {} B, B {} tris {} B; B hidden: A {} tris {} B (budget {}), \
         B {} B (roots {}), pending {}",
        a0.triangles,
        a0.gpu_resident_bytes,
        b0.triangles,
        b0.gpu_resident_bytes,
        a1.triangles,
        a1.gpu_resident_bytes,
        a1.gpu_budget_bytes,
        b1.gpu_resident_bytes,
        v.scheduler_of(1).pinned_bytes(),
        v.pager_stats_of(1).queued,
    );
    assert_eq!(b1.triangles, 0);
    assert!(v.last_draw_of(1).is_empty());
    assert_eq!(b1.gpu_resident_bytes, v.scheduler_of(1).pinned_bytes());
    assert_eq!(
        v.pager_stats_of(1).queued,
        0,
        "a hidden model asks for nothing"
    );
    assert!(
        a1.gpu_budget_bytes > a0.gpu_budget_bytes && a1.triangles > a0.triangles,
        "A gets B's memory: {a0:?} -> {a1:?}"
    );
    // B's half of the frame is background now.
    let right = |img: &Image| {
        (0..(W * H) as usize)
            .filter(|&x| x % W as usize > W as usize * 5 / 8 && covered(img, x))
            .count()
    };
    assert!(right(&img_both) > 3000, "B was drawn");
    assert_eq!(right(&img), 0, "B's pixels vanish");
    assert!(hidden.triangles == a1.triangles);
    // Shown again: B is drawn and gets memory back.
    v.set_visible(1, true);
    settle(&mut v, &cam, 1.0, 20.0);
    let b2 = v.model_stats(1).clone();
    assert!(b2.triangles > 0 && b2.gpu_resident_bytes > v.scheduler_of(1).pinned_bytes());
    assert!(right(&v.read_image().expect("read")) > 3000);
    let _ = before;
}

/// Two models sharing a tiny GPU budget while the camera moves around them: the split
/// moves memory back and forth every few frames, and no cut ever shows a crack.
#[test]
fn no_pinholes_with_two_models_and_a_tiny_budget() {
    let p = pair();
    // Below either model's fine cut (1.6 MB each), so both evict as the camera moves.
    // (Since the cache's buffers grow on demand instead of starting at their maxima,
    // 1152 KiB left model B always room on an idle machine: evictions [8, 0]; 896 KiB
    // gives [16, 8].)
    let budget = 896 << 10;
    let mut v = Viewer::with_models(
        gpu(),
        vec![reader(&p.a), reader(&p.b)],
        opts(Mode::Progressive, 0.3, budget),
    )
    .expect("scene");
    let frames = 60;
    let mut evictions = [0u64; 2];
    for i in 0..frames {
        let f = i as f64 / frames as f64;
        // Around the pair, nearer one model, then the other.
        let az = std::f64::consts::TAU * f * 1.5;
        let r = 4.5 + 2.0 * (f * 9.0).sin();
        let target = [2.0 + 1.5 * (az * 2.0).cos(), 0.0, 0.0];
        let pos = [
            target[0] + r * az.sin(),
            1.5 * (az * 3.0).sin(),
            r * az.cos(),
        ];
        let cam = camera(pos, target);
        let s = v.render(&cam).expect("render");
        assert!(s.gpu_resident_bytes <= budget, "frame {i}: {s:?}");
        let img = v.read_image().expect("read");
        let holes = enclosed_background_pixels(&img, BG);
        assert_eq!(holes, 0, "frame {i}: {holes} pinhole pixels ({s:?})");
        for (m, e) in evictions.iter_mut().enumerate() {
            *e = v.model_stats(m).gpu_evictions;
        }
        std::thread::sleep(Duration::from_millis(3));
    }
    eprintln!("evictions per model: {evictions:?}");
    assert!(evictions.iter().all(|&e| e > 0), "{evictions:?}");
}

/// Complete frames of a scene run model by model into one target: the same picture as
/// with an ample cache when the cache holds barely one model's cut.
#[test]
fn complete_frames_of_a_scene_with_a_small_cache() {
    let p = pair();
    let cam = camera([2.0, 0.5, 4.5], [2.0, 0.0, 0.0]);
    let render = |budget: u64| {
        let mut v = Viewer::with_models(
            gpu(),
            vec![reader(&p.a), reader(&p.b)],
            opts(Mode::Complete, 0.3, budget),
        )
        .expect("scene");
        let s = v.render(&cam).expect("render");
        (s, v.read_image().expect("read"))
    };
    let (one, a) = render(256 << 20);
    let (many, b) = render(256 << 10);
    assert_eq!(one.passes, 2, "one pass per model: {one:?}");
    assert!(many.passes > 2, "{many:?}");
    assert_eq!(one.triangles, many.triangles);
    let (off, max) = diff_stats(&a, &b, 0).expect("same size");
    eprintln!(
        "complete scene: {} triangles, {} passes in 256 KiB, {off} pixels differ (max {max})",
        many.triangles, many.passes
    );
    assert!(off <= 8, "{off} pixels differ");
}

/// A similarity that moves, turns and grows a model.
fn placement() -> Placement {
    Placement::new(
        DVec3::new(10.0, -3.0, 2.0),
        DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 70f64.to_radians()),
        2.5,
    )
    .expect("a similarity")
}

/// A placed model is drawn as a camera taken into its coordinates sees it (complete and
/// progressive frames): the placed scene seen from a world camera is the model alone seen
/// from that camera moved into the model's frame. The control: the same world camera
/// on the model left where its coordinates say sees nothing of it.
#[test]
fn a_placed_model_is_drawn_where_its_placement_puts_it() {
    let p = pair();
    let pl = placement();
    // Looking at A's placed centre from 2.2 placed radii away (the close-up of A).
    let local = camera([0.3, 0.4, 2.2], [0.0, 0.0, 0.0]);
    let world = Camera {
        position: pl.to_world(DVec3::from(local.position)).to_array(),
        target: pl.to_world(DVec3::from(local.target)).to_array(),
        up: pl.direction_to_world(DVec3::from(local.up)).to_array(),
        ..local.clone()
    };
    assert!(pl
        .camera_to_model(&world)
        .position
        .iter()
        .zip(local.position)
        .all(|(a, b)| (a - b).abs() < 1e-9));
    for mode in [Mode::Complete, Mode::Progressive] {
        let frame = |placed: Placement, cam: &Camera| {
            let mut v = Viewer::with_scene(
                gpu(),
                vec![(reader(&p.a), placed)],
                opts(mode, 1.0, 256 << 20),
            )
            .expect("viewer");
            let s = if mode == Mode::Progressive {
                settle(&mut v, cam, 0.0, 20.0)
            } else {
                v.render(cam).expect("render")
            };
            (s, v.read_image().expect("read"))
        };
        let (s_local, alone) = frame(Placement::IDENTITY, &local);
        let (s_placed, placed) = frame(pl, &world);
        let covered_px = (0..(W * H) as usize)
            .filter(|&x| covered(&alone, x))
            .count();
        let (off, max) = diff_stats(&alone, &placed, 16).expect("same size");
        eprintln!(
            "{mode:?}: {covered_px} px covered, triangles {} alone / {} placed, {off} px differ (max {max})",
            s_local.triangles,
            s_placed.triangles,
        );
        assert!(
            covered_px > 20_000,
            "the close-up fills the frame: {covered_px} px"
        );
        assert_eq!(s_local.triangles, s_placed.triangles, "the same cut");
        assert!(
            off <= covered_px / 500,
            "{mode:?}: {off} px differ (max {max})"
        );
        assert_eq!(enclosed_background_pixels(&placed, BG), 0);
        // The control: not placed, the world camera does not see that picture.
        let (_, unplaced) = frame(Placement::IDENTITY, &world);
        let (off, _) = diff_stats(&alone, &unplaced, 16).expect("same size");
        assert!(
            off > covered_px / 2,
            "{mode:?}: the unplaced model shows elsewhere ({off} px differ)"
        );
    }
}

/// Copies of one reader placed apart, overlapping on screen: one depth buffer (the
/// nearer copy hides the farther; planes fitted in world units over both), no crack in
/// either, the points picked on each lie on that copy.
#[test]
fn copies_of_one_model_share_depth_and_show_no_cracks() {
    let p = pair();
    let near = Placement::IDENTITY;
    let far = Placement::new(
        DVec3::new(1.2, 0.3, -4.0),
        DQuat::from_axis_angle(DVec3::Y, 2.0),
        1.8,
    )
    .expect("a similarity");
    let mut v = Viewer::with_scene(
        gpu(),
        vec![(reader(&p.a), near), (reader(&p.a), far)],
        opts(Mode::Progressive, 0.5, 256 << 20),
    )
    .expect("scene");
    let cam = camera([-0.4, 0.2, 4.0], [0.6, 0.1, -2.0]);
    let s = settle(&mut v, &cam, 0.0, 20.0);
    let img = v.read_image().expect("read");
    if std::env::var_os("TESSERA_TEST_TRACE").is_some() {
        img.save_png(&std::env::temp_dir().join("scene_copies.png"))
            .unwrap();
    }
    let (a, b) = (v.model_stats(0).triangles, v.model_stats(1).triangles);
    eprintln!(
        "copies: {} triangles ({a} near, {b} far), planes {:?}",
        s.triangles,
        v.clip_planes()
    );
    assert!(a > 0 && b > 0, "both copies drawn: {a} {b}");
    assert_eq!(enclosed_background_pixels(&img, BG), 0, "no crack");
    // The near copy's centre pixel shows the near copy; a pixel beside it, past its
    // silhouette, shows the far one (bigger, behind).
    let project = |x: DVec3| {
        let b = cam.basis();
        let d = x - DVec3::from(cam.position);
        let t = (0.5 * cam.fov_y_deg.to_radians()).tan();
        let z = d.dot(b.forward);
        (
            (d.dot(b.right) / z / (t * W as f64 / H as f64) + 1.0) * 0.5 * W as f64,
            (1.0 - d.dot(b.up) / z / t) * 0.5 * H as f64,
        )
    };
    // At the far copy's centre the near copy is in front (one depth buffer); beside
    // it, past the near copy's silhouette, the far copy shows.
    let b = cam.basis();
    for (at, on, name) in [
        (far.to_world(DVec3::ZERO), near, "near"),
        (far.to_world(DVec3::ZERO) + b.right * 1.5, far, "far"),
    ] {
        let (x, y) = project(at);
        let hit = DVec3::from(v.point_at(x, y).expect("depth").expect("a surface"));
        let d = on.to_model(hit).length();
        assert!(
            (0.9..1.1).contains(&d),
            "the point picked at {at} ({hit}) lies on the {name} copy: {d:.3} radii from its centre"
        );
    }
}

/// A distant copy drawn as a texture impostor (issue 31) looks like its geometry where
/// it was sampled: the frame with impostors and the frame without differ in few pixels,
/// the far copy's triangles are saved, no pinhole shows. The control: an impostor left
/// stale (never re-sampled) after the eye has turned around it differs far more.
#[test]
fn an_impostor_looks_like_its_geometry_until_the_eye_moves_on() {
    let p = pair();
    let far = Placement::new(DVec3::new(0.0, 0.0, -40.0), DQuat::IDENTITY, 4.0).expect("placed");
    let scene = || vec![(reader(&p.a), Placement::IDENTITY), (reader(&p.a), far)];
    let with = |max_error_px: f64| {
        let mut o = opts(Mode::Progressive, 1.0, 256 << 20);
        o.impostors = Some(tessera_render::ImpostorOptions {
            max_radius_px: 30.0,
            max_error_px,
            ..Default::default()
        });
        Viewer::with_scene(gpu(), scene(), o).expect("scene")
    };
    let frames = |v: &mut Viewer, cam: &Camera| {
        settle(v, cam, 0.0, 20.0);
        // The dissolve's frames, then one more.
        for _ in 0..10 {
            v.render(cam).expect("render");
        }
        v.read_image().expect("read")
    };
    let cam = camera([1.5, 0.5, 4.0], [0.0, 0.0, -20.0]);
    let mut geo =
        Viewer::with_scene(gpu(), scene(), opts(Mode::Progressive, 1.0, 256 << 20)).expect("scene");
    let reference = frames(&mut geo, &cam);
    let mut imp = with(1.5);
    let shot = frames(&mut imp, &cam);
    let st = imp.impostor_stats().expect("impostors on");
    let far_px = {
        // The far copy's pixels: the reference's model pixels off the near copy.
        let mut only_near = Viewer::with_scene(
            gpu(),
            vec![(reader(&p.a), Placement::IDENTITY)],
            opts(Mode::Progressive, 1.0, 256 << 20),
        )
        .expect("near");
        let near = frames(&mut only_near, &cam);
        (0..(W * H) as usize)
            .filter(|&x| covered(&reference, x) && !covered(&near, x))
            .count()
    };
    let (off, max) = diff_stats(&shot, &reference, 24).expect("same size");
    eprintln!(
        "impostor: {st:?}; far copy {far_px} px; {off} px differ by more than 24 (max {max})"
    );
    if std::env::var_os("TESSERA_TEST_TRACE").is_some() {
        shot.save_png(&std::env::temp_dir().join("impostor_on.png"))
            .unwrap();
        reference
            .save_png(&std::env::temp_dir().join("impostor_off.png"))
            .unwrap();
    }
    assert_eq!(st.impostors, 1, "the far copy is an impostor: {st:?}");
    assert!(st.triangles_saved > 0 && st.texture_bytes > 0, "{st:?}");
    assert!(far_px > 800, "the far copy shows: {far_px} px");
    // Sampled over the frame's own pixels: the same rasterisation (measured: 0 px).
    assert!(
        off <= far_px / 100,
        "{off} px differ (far copy {far_px} px)"
    );
    assert_eq!(enclosed_background_pixels(&shot, BG), 0);

    // The eye turns 25 degrees around the far copy (its centre at z = -40).
    let turn = 25f64.to_radians();
    let (cx, cz, d) = (0.0, -40.0, 44.0);
    let moved = camera(
        [cx + d * turn.sin(), 0.5, cz + d * turn.cos()],
        [0.0, 0.0, -40.0],
    );
    let reference = frames(&mut geo, &moved);
    let fresh = frames(&mut imp, &moved);
    let mut stale_v = with(1e9);
    frames(&mut stale_v, &cam);
    let stale = frames(&mut stale_v, &moved);
    let (fresh_off, _) = diff_stats(&fresh, &reference, 24).expect("same size");
    let (stale_off, _) = diff_stats(&stale, &reference, 24).expect("same size");
    eprintln!("after turning: re-sampled {fresh_off} px differ, never re-sampled {stale_off} px");
    assert!(
        stale_off > 2 * fresh_off.max(20),
        "the stale control must differ more: {stale_off} vs {fresh_off}"
    );
}
