//! CPU cost of one frame of residency-aware selection + prefetch (issue 3 target: <= 1 ms
//! at 10^5 nodes).
//!
//! Builds a deterministic synthetic forest in memory: 6 roots, each a 60-degree longitude
//! sector of a unit sphere, bisected alternately in longitude and latitude down to
//! `depth` levels (6 * (2^(depth+1) - 1) nodes; 196,602 at the default depth 14). Tight
//! spheres bound sample points of each lat/long patch, normal cones bound their normals,
//! saturated spheres are built bottom-up. Errors are 1/32 of the node's radius (the
//! simplification error of a ~1000-triangle patch; on a surface the patch size halves
//! every two levels), saturated bottom-up, leaves 0: at 1 px tolerance and 1080 px a close
//! view draws a few thousand nodes, like a real model. Then times
//! `select_resident` (everything resident) + `prefetch_set` (growth 1.5, linear
//! prediction from the previous frame) over 200 frames along orbits at several distances,
//! and the geomorphing ratios of the drawn nodes (issue 10 target: selection + ratios
//! <= 1 ms at 10^5 nodes): `group_ratio` once per group of siblings (here a node's two
//! children; a real diamond's group has 4-12), as the scheduler does.
//!
//! `cargo run --release -p tessera-select --example bench_select [depth] [frames] [tolerance_px]`

use std::time::Instant;

use bytemuck::Zeroable;
use glam::Vec3;
use tessera_format::{Header, NodeRecord, NO_NODE};
use tessera_select::{
    group_ratio, predict_camera, prefetch_set, select_resident, Camera, NodeView, Orbit,
    PrefetchOptions, Selection, ViewParams, DEFAULT_MORPH_WINDOW,
};

struct Region {
    lon: [f64; 2],
    lat: [f64; 2],
    level: u8,
}

fn dir(lon: f64, lat: f64) -> Vec3 {
    Vec3::new(
        (lat.cos() * lon.cos()) as f32,
        lat.sin() as f32,
        (lat.cos() * lon.sin()) as f32,
    )
}

fn samples(r: &Region) -> Vec<Vec3> {
    let mut v = Vec::with_capacity(25);
    for i in 0..5 {
        for j in 0..5 {
            let lon = r.lon[0] + (r.lon[1] - r.lon[0]) * f64::from(i) / 4.0;
            let lat = r.lat[0] + (r.lat[1] - r.lat[0]) * f64::from(j) / 4.0;
            v.push(dir(lon, lat));
        }
    }
    v
}

fn forest(depth: u8) -> (Header, Vec<NodeRecord>) {
    use std::f64::consts::PI;
    let mut regions: Vec<Region> = (0..6)
        .map(|k| Region {
            lon: [f64::from(k) * PI / 3.0, f64::from(k + 1) * PI / 3.0],
            lat: [-PI / 2.0, PI / 2.0],
            level: 0,
        })
        .collect();
    let mut nodes: Vec<NodeRecord> = Vec::new();
    // Breadth-first: the table is ordered by level, children after parents.
    let mut i = 0;
    while i < regions.len() {
        let (lon, lat, level) = (regions[i].lon, regions[i].lat, regions[i].level);
        let pts = samples(&regions[i]);
        let centre = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
        let radius = pts.iter().map(|p| p.distance(centre)).fold(0.0, f32::max) * 1.01;
        let axis = centre.normalize_or(Vec3::Y);
        let cos = pts.iter().map(|p| p.dot(axis)).fold(1.0, f32::min) - 0.01;
        let mut n = NodeRecord {
            level,
            tight_sphere: [centre.x, centre.y, centre.z, radius],
            saturated_sphere: [centre.x, centre.y, centre.z, radius],
            normal_cone: [axis.x, axis.y, axis.z, cos.max(-1.0)],
            error: if level == depth { 0.0 } else { radius / 32.0 },
            children: [NO_NODE; 2],
            parent: NO_NODE,
            triangle_count: 1000,
            ..NodeRecord::default()
        };
        if level < depth {
            let first = regions.len() as u32;
            n.children = [first, first + 1];
            let halves = if level % 2 == 0 {
                let m = 0.5 * (lon[0] + lon[1]);
                [([lon[0], m], lat), ([m, lon[1]], lat)]
            } else {
                let m = 0.5 * (lat[0] + lat[1]);
                [(lon, [lat[0], m]), (lon, [m, lat[1]])]
            };
            for (lo, la) in halves {
                regions.push(Region {
                    lon: lo,
                    lat: la,
                    level: level + 1,
                });
            }
        }
        nodes.push(n);
        i += 1;
    }
    // Parents, then saturated spheres bottom-up (children come after parents).
    for p in 0..nodes.len() {
        for c in nodes[p].children {
            if c != NO_NODE {
                nodes[c as usize].parent = p as u32;
            }
        }
    }
    for p in (0..nodes.len()).rev() {
        let mut s = nodes[p].saturated_sphere;
        for c in nodes[p].children {
            if c == NO_NODE {
                continue;
            }
            let cs = nodes[c as usize].saturated_sphere;
            let d = Vec3::new(cs[0] - s[0], cs[1] - s[1], cs[2] - s[2]).length();
            s[3] = s[3].max(d + cs[3]);
            nodes[p].error = nodes[p].error.max(nodes[c as usize].error);
        }
        nodes[p].saturated_sphere = s;
    }
    let mut h = Header::zeroed();
    h.root_count = 6;
    h.node_count = nodes.len() as u64;
    h.level_count = u32::from(depth) + 1;
    (h, nodes)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let depth: u8 = args.next().and_then(|a| a.parse().ok()).unwrap_or(14);
    let frames: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(200);
    let tolerance_px: f32 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1.0);
    let t = Instant::now();
    let (header, nodes) = forest(depth);
    let built = t.elapsed();
    let t = Instant::now();
    let nv = NodeView::new(&header, &nodes);
    println!(
        "forest: {} nodes, depth {depth}, built in {:.0} ms; NodeView in {:.1} ms",
        nodes.len(),
        built.as_secs_f64() * 1e3,
        t.elapsed().as_secs_f64() * 1e3
    );
    let mut sel = Selection::default();
    let mut pre = Vec::new();
    for radius in [4.0, 2.0, 1.3, 1.05] {
        let cam_at = |f: usize| {
            Camera::orbit(&Orbit {
                radius,
                azimuth_deg: 360.0 * f as f64 / frames as f64,
                elevation_deg: 20.0,
                width: 1920,
                height: 1080,
                ..Orbit::default()
            })
            .unwrap()
        };
        let mut times = Vec::with_capacity(frames);
        let mut sel_times = Vec::with_capacity(frames);
        let mut morph_times = Vec::with_capacity(frames);
        // Per parent: the frame its group's ratio was computed in, and the ratio.
        let mut memo: Vec<(usize, f32)> = vec![(usize::MAX, 0.0); nodes.len()];
        let mut ratios: Vec<f32> = Vec::new();
        let mut morphing = 0usize;
        let (mut visited, mut drawn, mut prefetched) = (0usize, 0usize, 0usize);
        let mut prev = cam_at(0);
        // Frame 0 is a warm-up (output vectors grow to size), not timed.
        for f in 0..=frames {
            let cam = cam_at(f);
            let t = Instant::now();
            let view = ViewParams::new(&cam, header.cube_origin, tolerance_px, true);
            select_resident(&nv, &view, &|_| true, &mut sel);
            let t_sel = t.elapsed().as_secs_f64() * 1e6;
            let tm = Instant::now();
            ratios.clear();
            for &n in &sel.draw {
                let p = nv.nodes()[n as usize].parent;
                if p == NO_NODE {
                    ratios.push(0.0);
                    continue;
                }
                if memo[p as usize].0 != f {
                    let members = nv.nodes()[p as usize].children;
                    memo[p as usize] = (f, group_ratio(&nv, &view, &members, DEFAULT_MORPH_WINDOW));
                }
                ratios.push(memo[p as usize].1);
            }
            let t_morph = tm.elapsed().as_secs_f64() * 1e6;
            let opts = PrefetchOptions {
                sphere_growth: 1.5,
                predicted: Some(predict_camera(&prev, &cam, 1.0 / 60.0, 0.25)),
            };
            let pre_visited = prefetch_set(&nv, &view, &opts, &mut pre);
            if f == 0 {
                continue;
            }
            times.push(t.elapsed().as_secs_f64() * 1e6);
            sel_times.push(t_sel);
            morph_times.push(t_sel + t_morph);
            morphing += ratios.iter().filter(|&&r| r > 0.0).count();
            visited += sel.visited + pre_visited;
            drawn += sel.draw.len();
            prefetched += pre.len();
            std::hint::black_box((&sel, &pre));
            prev = cam;
        }
        times.sort_by(f64::total_cmp);
        sel_times.sort_by(f64::total_cmp);
        morph_times.sort_by(f64::total_cmp);
        println!(
            "orbit radius {radius}: select_resident + prefetch_set per frame: best {:.1} us, \
             median {:.1} us, p95 {:.1} us, worst {:.1} us (select_resident alone: median \
             {:.1} us; select_resident + morph ratios: median {:.1} us, worst {:.1} us); \
             mean per frame: {} visited (both), {} drawn ({} morphing), {} prefetched",
            times[0],
            times[times.len() / 2],
            times[times.len() * 95 / 100],
            times[times.len() - 1],
            sel_times[sel_times.len() / 2],
            morph_times[morph_times.len() / 2],
            morph_times[morph_times.len() - 1],
            visited / frames,
            drawn / frames,
            morphing / frames,
            prefetched / frames
        );
    }
}
