//! Scratch lab for the morph codec (temporary).
use std::collections::HashMap;
use std::io::{Read, Write};
use tessera_format::{Model, PatchData};

pub struct P { attrs: u32, qmin: [u32; 3], p: PatchData }

fn w32(o: &mut Vec<u8>, v: u32) { o.extend_from_slice(&v.to_le_bytes()); }

fn dump(model: &str, out: &str) {
    let m = Model::open(model).unwrap();
    let attrs = m.header().attributes;
    let mut o = Vec::new();
    println!("input triangles {}", m.header().input_triangles);
    w32(&mut o, m.header().input_triangles as u32);
    for (i, n) in m.nodes().iter().enumerate() {
        let p = m.decode_patch(i).unwrap();
        w32(&mut o, attrs); for k in 0..3 { w32(&mut o, n.quant_min[k]); }
        w32(&mut o, p.positions.len() as u32); w32(&mut o, p.indices.len() as u32);
        w32(&mut o, p.normals.len() as u32); w32(&mut o, p.morph_targets.len() as u32);
        for q in &p.positions { for k in 0..3 { w32(&mut o, q[k]); } }
        for q in &p.normals { for k in 0..3 { w32(&mut o, q[k].to_bits()); } }
        for q in &p.morph_targets { for k in 0..3 { w32(&mut o, q[k]); } }
        for &q in &p.indices { w32(&mut o, q); }
    }
    std::fs::File::create(out).unwrap().write_all(&o).unwrap();
}

pub fn load(path: &str) -> (u64, Vec<P>) {
    let mut b = Vec::new();
    std::fs::File::open(path).unwrap().read_to_end(&mut b).unwrap();
    let at = std::cell::Cell::new(0usize);
    let r = || { let a = at.get(); let v = u32::from_le_bytes(b[a..a + 4].try_into().unwrap()); at.set(a + 4); v };
    let input = r() as u64;
    let mut v = Vec::new();
    loop {
        // peek
        let attrs = r();
        let qmin = [r(), r(), r()];
        let (n, ni, nn, nm) = (r() as usize, r() as usize, r() as usize, r() as usize);
        let mut p = PatchData::default();
        for _ in 0..n { p.positions.push([r(), r(), r()]); }
        for _ in 0..nn { p.normals.push([f32::from_bits(r()), f32::from_bits(r()), f32::from_bits(r())]); }
        for _ in 0..nm { p.morph_targets.push([r(), r(), r()]); }
        for _ in 0..ni { p.indices.push(r()); }
        v.push(P { attrs, qmin, p });
        if at.get() >= b.len() { break; }
    }
    (input, v)
}

fn stats(ps: &[P]) {
    let (mut verts, mut tris, mut stays, mut inpatch, mut nbr, mut explicit, mut dupl) = (0usize, 0usize, 0, 0, 0, 0, 0);
    let mut hist: HashMap<i64, usize> = HashMap::new();
    let mut morph_patches = 0;
    let mut sizes = vec![];
    for P { p, .. } in ps {
        verts += p.vertex_count(); tris += p.triangle_count();
        sizes.push(p.triangle_count());
        if p.morph_targets.is_empty() { continue; }
        morph_patches += 1;
        let mut map: HashMap<[u32; 3], Vec<u32>> = HashMap::new();
        for (i, q) in p.positions.iter().enumerate() { map.entry(*q).or_default().push(i as u32); }
        let mut adj: Vec<Vec<u32>> = vec![vec![]; p.vertex_count()];
        for t in p.indices.chunks(3) { for a in 0..3 { for b in 0..3 { if a != b { adj[t[a] as usize].push(t[b]); } } } }
        for (i, (q, t)) in p.positions.iter().zip(&p.morph_targets).enumerate() {
            if q == t { stays += 1; continue; }
            match map.get(t) {
                None => explicit += 1,
                Some(c) => {
                    inpatch += 1;
                    if c.len() > 1 { dupl += 1; }
                    let best = *c.iter().min_by_key(|&&j| (j as i64 - i as i64).abs()).unwrap();
                    *hist.entry(best as i64 - i as i64).or_default() += 1;
                    if c.iter().any(|j| adj[i].contains(j)) { nbr += 1; }
                }
            }
        }
    }
    sizes.sort();
    println!("patches {} (morph {morph_patches}), verts {verts}, tris {tris}, v/t {:.3}; patch tris median {} max {}", ps.len(), verts as f64 / tris as f64, sizes[sizes.len()/2], sizes.last().unwrap());
    let m = stays + inpatch + explicit;
    println!("morph verts {m}: stays {:.3} inpatch {:.3} (neighbour {:.3}, dup-pos {dupl}) explicit {:.3}", stays as f64 / m as f64, inpatch as f64 / m as f64, nbr as f64 / m as f64, explicit as f64 / m as f64);
    let mut h: Vec<_> = hist.into_iter().collect(); h.sort_by_key(|x| std::cmp::Reverse(x.1));
    let tot: usize = h.iter().map(|x| x.1).sum();
    let ent: f64 = h.iter().map(|x| { let p = x.1 as f64 / tot as f64; -p * p.log2() }).sum();
    println!("ref delta entropy {ent:.2} bits; top: {:?}", &h[..20.min(h.len())]);
    let mut within = [0usize; 6];
    for (d, c) in &h { for (k, lim) in [7i64, 15, 63, 127, 1023, 1 << 20].iter().enumerate() { if d.abs() <= *lim { within[k] += c; } } }
    println!("|d|<=7,15,63,127,1023,inf: {:?}", within.map(|w| format!("{:.3}", w as f64 / tot as f64)));
}


fn zz(v: i32) -> u32 { ((v << 1) ^ (v >> 31)) as u32 }
fn venc<T>(v: &[T]) -> Vec<u8> { if v.is_empty() { return vec![]; } meshopt::encode_vertex_buffer_level(v, 3, Some(1)).unwrap() }
fn varint(o: &mut Vec<u8>, mut v: u32) { while v >= 0x80 { o.push((v as u8) | 0x80); v >>= 7; } o.push(v as u8); }

/// Morph codes: 0 stays, 1 explicit, else zz(ref-i)+2. Returns (codes, explicit deltas)
fn morph_codes(p: &PatchData) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut map: HashMap<[u32; 3], Vec<u32>> = HashMap::new();
    for (i, q) in p.positions.iter().enumerate() { map.entry(*q).or_default().push(i as u32); }
    let mut codes = vec![]; let mut ex = vec![];
    for (i, (q, t)) in p.positions.iter().zip(&p.morph_targets).enumerate() {
        if q == t { codes.push(0); continue; }
        match map.get(t) {
            None => { codes.push(1); ex.push(std::array::from_fn(|k| zz(t[k].wrapping_sub(q[k]) as i32))); }
            Some(c) => { let best = *c.iter().min_by_key(|&&j| (j as i64 - i as i64).abs()).unwrap(); codes.push(zz(best as i32 - i as i32) + 2); }
        }
    }
    (codes, ex)
}
/// neighbour-rank codes: 0 stays, 1 explicit, 2 + rank among adjacency (first-seen order), else 2+deg+zz(d)
fn morph_rank(p: &PatchData) -> Vec<u8> {
    let (codes, ex) = morph_codes(p);
    let n = p.vertex_count();
    let mut adj: Vec<Vec<u32>> = vec![vec![]; n];
    for t in p.indices.chunks(3) { for a in 0..3 { for b in 1..3 { let j = t[(a + b) % 3]; let l = &mut adj[t[a] as usize]; if !l.contains(&j) { l.push(j); } } } }
    let mut o = vec![];
    for (i, &c) in codes.iter().enumerate() {
        if c < 2 { o.push(c as u8); continue; }
        let d = (c - 2) as i32; let d = ((d >> 1) ^ -(d & 1)) as i32; let r = (i as i32 + d) as u32;
        // rank among neighbours that stay
        let cand: Vec<u32> = adj[i].iter().copied().filter(|&j| codes[j as usize] == 0).collect();
        match cand.iter().position(|&j| j == r) { Some(k) => o.push(2 + k as u8), None => { o.push(40); varint(&mut o, c); } }
    }
    let _ = ex; o
}

fn morph_survivor(p: &PatchData) -> (Vec<u32>, Vec<[u32; 3]>) {
    let n = p.vertex_count();
    let stays: Vec<bool> = (0..n).map(|i| p.positions[i] == p.morph_targets[i]).collect();
    let mut rank = vec![0u32; n + 1];
    for i in 0..n { rank[i + 1] = rank[i] + stays[i] as u32; }
    let mut map: HashMap<[u32; 3], Vec<u32>> = HashMap::new();
    for (i, q) in p.positions.iter().enumerate() { if stays[i] { map.entry(*q).or_default().push(i as u32); } }
    let mut codes = vec![]; let mut ex = vec![]; let mut fb = 0;
    for (i, (q, t)) in p.positions.iter().zip(&p.morph_targets).enumerate() {
        if q == t { codes.push(0); continue; }
        match map.get(t) {
            None => { if p.positions.contains(t) { fb += 1; } codes.push(1); ex.push(std::array::from_fn(|k| zz(t[k].wrapping_sub(q[k]) as i32))); }
            Some(c) => { let best = *c.iter().min_by_key(|&&j| (j as i64 - i as i64).abs()).unwrap(); codes.push(zz(rank[best as usize] as i32 - rank[i] as i32) + 2); }
        }
    }
    if fb > 0 { eprintln!("nonstay target {fb}"); }
    (codes, ex)
}

fn sections(p: &PatchData, qmin: [u32; 3], morph: u32) -> Vec<Vec<u8>> {
    let n = p.vertex_count();
    let mut s = vec![vec![]; 6];
    if n == 0 { return s; }
    if !p.indices.is_empty() { s[0] = meshopt::encode_index_buffer(&p.indices, n).unwrap(); }
    let rel: Vec<[u32; 3]> = p.positions.iter().map(|q| std::array::from_fn(|k| q[k] - qmin[k])).collect();
    s[1] = venc(&rel);
    if !p.normals.is_empty() {
        let oct: Vec<[u8; 4]> = p.normals.iter().map(|&v| { let e = tessera_format::oct_encode(v); [e[0], e[1], 0, 0] }).collect();
        s[2] = venc(&oct);
    }
    if !p.morph_targets.is_empty() {
        match morph {
            0 => { let d: Vec<[u32; 3]> = p.positions.iter().zip(&p.morph_targets).map(|(q, t)| std::array::from_fn(|k| zz(t[k].wrapping_sub(q[k]) as i32))).collect(); s[5] = venc(&d); }
            1 => { let (c, e) = morph_codes(p); s[5] = venc(&c); s[4] = venc(&e); }
            2 => { let (c, e) = morph_codes(p); for x in c { varint(&mut s[5], x); } s[4] = venc(&e); }
            3 => { let (_, e) = morph_codes(p); s[5] = morph_rank(p); s[4] = venc(&e); }
            4 => { let (c, e) = morph_codes(p); for x in c { varint(&mut s[5], x); } let mut raw = vec![]; for q in e { for k in 0..3 { varint(&mut raw, q[k]); } } s[4] = raw; }
            6 => { let (c, e) = morph_survivor(p); for x in c { varint(&mut s[5], x); } s[4] = venc(&e); }
            _ => {}
        }
    }
    s
}

fn eval(input: u64, ps: &[P], morph: u32, level: i32, sep_morph: bool) {
    let (mut tot, mut tris, mut msec) = (0usize, 0usize, 0usize);
    for P { p, qmin, .. } in ps {
        tris += p.triangle_count();
        let s = sections(p, *qmin, morph);
        msec += s[5].len() + s[4].len();
        let z = |b: &[u8]| if b.is_empty() { 0 } else { zstd::bulk::compress(b, level).unwrap().len().min(b.len()) };
        tot += 40 + if sep_morph { z(&s[..4].concat()) + z(&s[4..].concat()) } else { z(&s.concat()) };
    }
    println!("morph={morph} zstd={level} sep={sep_morph}: {:.3} B/stored tri, {:.3} B/input tri; morph raw {:.3} B/tri", tot as f64 / tris as f64, tot as f64 / input as f64, msec as f64 / tris as f64);
}

fn real(input: u64, ps: &[P]) {
    let t0 = std::time::Instant::now();
    let enc: Vec<Vec<u8>> = ps.iter().map(|x| tessera_format::encode_patch(&x.p, x.attrs, x.qmin)).collect();
    let et = t0.elapsed();
    let nomorph: usize = ps.iter().map(|x| tessera_format::encode_patch(&PatchData { morph_targets: vec![], ..x.p.clone() }, x.attrs, x.qmin).len()).sum();
    let tot: usize = enc.iter().map(|e| e.len()).sum();
    let tris: usize = ps.iter().map(|x| x.p.triangle_count()).sum();
    for (x, e) in ps.iter().zip(&enc) {
        let d = tessera_format::decode_patch(e, x.attrs, x.qmin, x.p.vertex_count() as u32, x.p.triangle_count() as u32).unwrap();
        assert_eq!(d.positions, x.p.positions); assert_eq!(d.morph_targets, x.p.morph_targets);
    }
    let reps = 5;
    let nm: Vec<(Vec<u8>, &P)> = ps.iter().map(|x| (tessera_format::encode_patch(&PatchData { morph_targets: vec![], ..x.p.clone() }, x.attrs, x.qmin), x)).collect();
    for _ in 0..2 {
    let t0 = std::time::Instant::now();
    for _ in 0..reps { for (e, x) in &nm {
        std::hint::black_box(tessera_format::decode_patch(e, x.attrs, x.qmin, x.p.vertex_count() as u32, x.p.triangle_count() as u32).unwrap());
    } }
    println!("no-morph decode {:.1} Mtri/s", tris as f64 / (t0.elapsed().as_secs_f64() / reps as f64) / 1e6);
    let t0 = std::time::Instant::now();
    for _ in 0..reps { for (x, e) in ps.iter().zip(&enc) {
        std::hint::black_box(tessera_format::decode_patch(e, x.attrs, x.qmin, x.p.vertex_count() as u32, x.p.triangle_count() as u32).unwrap());
    } }
    println!("morph decode {:.1} Mtri/s", tris as f64 / (t0.elapsed().as_secs_f64() / reps as f64) / 1e6);
    }
    let t0 = std::time::Instant::now();
    for _ in 0..reps { for (x, e) in ps.iter().zip(&enc) {
        std::hint::black_box(tessera_format::decode_patch(e, x.attrs, x.qmin, x.p.vertex_count() as u32, x.p.triangle_count() as u32).unwrap());
    } }
    let dt = t0.elapsed().as_secs_f64() / reps as f64;
    println!("real codec: {:.3} B/stored tri ({:.3} B/input tri), morph {:.3} B/tri; encode {:.2}s; decode {:.1} Mtri/s", tot as f64 / tris as f64, tot as f64 / input as f64, (tot - nomorph) as f64 / tris as f64, et.as_secs_f64(), tris as f64 / dt / 1e6);
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    match a[1].as_str() {
        "dump" => dump(&a[2], &a[3]),
        "stats" => { let (_, ps) = load(&a[2]); stats(&ps); }
        "eval" => { let (inp, ps) = load(&a[2]); let m: u32 = a[3].parse().unwrap(); let l: i32 = a[4].parse().unwrap(); eval(inp, &ps, m, l, a.len() > 5); }
        "real" => { let (inp, ps) = load(&a[2]); real(inp, &ps); }
        _ => panic!(),
    }
}
