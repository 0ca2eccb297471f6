//! Close-ups where the folds are (`viz::closeup`) and the animated PNG writer. Set
//! ANISOCB_SAVE_PICTURES=DIR to write the pictures these tests draw for a look.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::geom::GridMesh;
use anisocb::viz::closeup::{closeup_rows, flipbook_frames, wrinkle_window, Frame, Patch};
use anisocb::viz::image::Rgb8;
use tempdir::TempDir;

fn save(name: &str, img: &Rgb8) {
    #[cfg(feature = "cli")]
    if let Ok(dir) = std::env::var("ANISOCB_SAVE_PICTURES") {
        anisocb::app::ui::save_png(&std::path::Path::new(&dir).join(name), img).unwrap();
    }
    #[cfg(not(feature = "cli"))]
    let _ = (name, img);
}

/// A 1 m sheet on an `n × n` grid, gently bent (a large-scale shape every grid holds), with
/// folds of `amp` metres and a 3-vertex wavelength (finer than the LR grid holds) on columns
/// and rows `lo..hi`.
fn sheet_with_folds(n: usize, amp: f32, lo: usize, hi: usize) -> GridMesh {
    let mut m = GridMesh::flat(n, n, 1.0, 1.0);
    for j in 0..n {
        for i in 0..n {
            let p = &mut m.pos[j * n + i];
            p[2] = 0.03 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos();
            if (lo..hi).contains(&i) && (lo..hi).contains(&j) {
                p[2] += amp * (2.0 * std::f32::consts::PI * (i + j) as f32 / 3.0).sin();
            }
        }
    }
    m
}

/// Every 2nd vertex of a ×2 grid of odd size, or the nearest one (the LR grid's vertices).
fn lr_of(hr: &GridMesh, lw: usize) -> GridMesh {
    let at = |k: usize| (k * (hr.w - 1) + (lw - 1) / 2) / (lw - 1);
    let pos = (0..lw).flat_map(|j| (0..lw).map(move |i| (i, j))).map(|(i, j)| hr.pos[at(j) * hr.w + at(i)]);
    GridMesh::new(lw, lw, pos.collect())
}

fn centre(p: &Patch) -> (usize, usize) {
    (p.i0 + p.w / 2, p.j0 + p.h / 2)
}

#[test]
fn window_picker_finds_the_folded_corner() {
    // Folds on vertices 40..62 of 64 (lower right); the 12-LR-vertex window must sit on them.
    let hr = sheet_with_folds(64, 0.002, 40, 62);
    let win = wrinkle_window(&hr, 32, 32, 12).unwrap();
    let (ci, cj) = centre(&win.hr);
    assert!((40..62).contains(&ci) && (40..62).contains(&cj), "window {win:?}");
    assert_eq!((win.lr.w, win.lr.h), (12, 12));
    // The HR patch covers the LR patch's span (LR 32 → HR 64, align corners).
    assert_eq!(win.hr.i0, (win.lr.i0 * 63).div_ceil(31));
    assert_eq!(win.hr.i0 + win.hr.w - 1, (win.lr.i0 + 11) * 63 / 31);
    // The same folds in the upper left move the window there.
    let hr = sheet_with_folds(64, 0.002, 2, 24);
    let win = wrinkle_window(&hr, 32, 32, 12).unwrap();
    let (ci, cj) = centre(&win.hr);
    assert!((2..24).contains(&ci) && (2..24).contains(&cj), "window {win:?}");
}

#[test]
fn window_picker_rejects_an_lr_grid_larger_than_the_truth() {
    let hr = GridMesh::flat(16, 16, 1.0, 1.0);
    assert!(wrinkle_window(&hr, 32, 32, 12).is_err());
    assert!(wrinkle_window(&hr, 8, 8, 1).is_err());
}

/// Variance of the colour (summed over R, G, B) of the cloth's pixels: those that are not
/// grey (the background is a grey gradient, the normal shading's colours are not grey).
fn cloth_colour_variance(img: &Rgb8) -> f64 {
    let px: Vec<[f64; 3]> = img
        .data
        .chunks(3)
        .filter(|c| c.iter().max().unwrap() - c.iter().min().unwrap() > 30)
        .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
        .collect();
    assert!(px.len() > img.w * img.h / 2, "cloth covers {} of {} pixels", px.len(), img.w * img.h);
    (0..3)
        .map(|k| {
            let mean = px.iter().map(|p| p[k]).sum::<f64>() / px.len() as f64;
            px.iter().map(|p| (p[k] - mean).powi(2)).sum::<f64>() / px.len() as f64
        })
        .sum()
}

/// A picture's `w`-px-wide tile `k` of a row of tiles `gap` px apart.
fn tile(img: &Rgb8, k: usize, w: usize, gap: usize) -> Rgb8 {
    let mut out = Rgb8::new(w, img.h, [0; 3]);
    for y in 0..img.h {
        for x in 0..w {
            out.set(x, y, img.get(k * (w + gap) + x, y));
        }
    }
    out
}

#[test]
fn closeup_of_millimetre_folds_shows_more_variation_than_a_smooth_sheet() {
    // Folds of 1 mm on a 64² grid of a 1 m sheet (1.6 cm per cell): what the close-ups are for.
    let folded = sheet_with_folds(64, 0.001, 20, 50);
    let smooth = sheet_with_folds(64, 0.0, 20, 50);
    let (lr_f, lr_s) = (lr_of(&folded, 32), lr_of(&smooth, 32));
    let frame = |lr, hr| Frame { lr, catmull_rom: hr, ours: hr, ours_label: "anisocb", truth: hr };
    let a = closeup_rows(&[(0, frame(&lr_f, &folded))], 12, 128).unwrap();
    let b = closeup_rows(&[(0, frame(&lr_s, &smooth))], 12, 128).unwrap();
    save("closeup-folded.png", &a);
    save("closeup-smooth.png", &b);
    assert_eq!((a.w, a.h), (4 * 128 + 3 * 6, 128));
    // The HR tile (the 4th): folds make the colour vary far more than the smooth bend does.
    let (va, vb) = (cloth_colour_variance(&tile(&a, 3, 128, 6)), cloth_colour_variance(&tile(&b, 3, 128, 6)));
    assert!(va > 2.0 * vb, "variance folded {va:.1} vs smooth {vb:.1}");
}

#[test]
fn flipbook_has_every_frame_up_to_60_and_every_2nd_above() {
    let hr = sheet_with_folds(32, 0.002, 4, 14);
    let lr = lr_of(&hr, 16);
    let f = Frame { lr: &lr, catmull_rom: &hr, ours: &hr, ours_label: "anisocb", truth: &hr };
    let frames = flipbook_frames(&vec![f; 61], 6, 48).unwrap();
    assert_eq!(frames.len(), 31);
    assert!(frames.iter().all(|p| (p.w, p.h) == (frames[0].w, frames[0].h)));
    assert_eq!(flipbook_frames(&vec![f; 60], 6, 48).unwrap().len(), 60);
    assert!(flipbook_frames(&[], 6, 48).is_err());
}

#[test]
fn patch_cut_keeps_rows_and_columns() {
    let m = GridMesh::flat(5, 4, 1.0, 1.0);
    let p = Patch { i0: 1, j0: 2, w: 3, h: 2 };
    let c = p.cut(&m).unwrap();
    assert_eq!((c.w, c.h), (3, 2));
    assert_eq!(c.pos[0], m.pos[2 * 5 + 1]);
    assert_eq!(c.pos[5], m.pos[3 * 5 + 3]);
    assert!(Patch { i0: 3, ..p }.cut(&m).is_err());
}

#[cfg(feature = "cli")]
#[test]
fn apng_writer_writes_an_animation_png_decodes_frame_by_frame() {
    let dir = TempDir::new("apng");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("flip.png");
    let frames: Vec<Rgb8> = (0..5u8).map(|k| Rgb8::new(7, 3, [40 * k, 255 - 40 * k, 9])).collect();
    anisocb::app::ui::save_apng(&path, &frames, 15).unwrap();
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let actl = *reader.info().animation_control().expect("an animated PNG");
    assert_eq!((actl.num_frames, actl.num_plays), (5, 0));
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    for (k, want) in frames.iter().enumerate() {
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (7, 3));
        assert_eq!(&buf[..info.buffer_size()], &want.data[..], "frame {k}");
        let fc = reader.info().frame_control().expect("frame control");
        assert_eq!((fc.delay_num, fc.delay_den), (1, 15));
    }
    assert!(reader.next_frame(&mut buf).is_err(), "more frames than written");
    // Frames of different sizes are refused, and nothing is left behind.
    let bad = [Rgb8::new(2, 2, [0; 3]), Rgb8::new(3, 2, [0; 3])];
    let other = dir.join("bad.png");
    assert!(anisocb::app::ui::save_apng(&other, &bad, 15).is_err());
    assert!(!other.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Frames of an animated PNG as the `png` crate decodes them (the count in its `acTL` chunk,
/// checked against the frames actually there).
#[cfg(feature = "cli")]
fn apng_frames(path: &std::path::Path) -> usize {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let n = reader.info().animation_control().expect("an animated PNG").num_frames as usize;
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    for k in 0..n {
        reader.next_frame(&mut buf).unwrap_or_else(|e| panic!("frame {k} of {n}: {e}"));
    }
    n
}

#[cfg(feature = "cli")]
#[test]
fn demo_writes_wrinkles_png_and_eval_flipbook_writes_an_animation() {
    use std::process::Command;
    let dir = TempDir::new("closeups");
    let demo = dir.join("demo");
    let o = Command::new(env!("CARGO_BIN_EXE_anisocb"))
        .args(["demo", "--frames", "8", "--out", demo.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "demo failed: {}", String::from_utf8_lossy(&o.stderr));
    assert!(demo.join("wrinkles.png").is_file());
    assert!(String::from_utf8_lossy(&o.stdout).contains("wrinkles.png"), "the listing names wrinkles.png");
    let out = dir.join("eval");
    let run = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_anisocb"))
            .args(["eval", "--runs", demo.join("sim").to_str().unwrap(), "--out", out.to_str().unwrap()])
            .args(["--eta", "0", "--worst", "0"])
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "eval failed: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let said = run(&[]);
    assert!(out.join("sim-wrinkles.png").is_file() && said.contains("-wrinkles.png"), "{said}");
    assert!(!out.join("sim-flipbook.png").exists(), "the flip-book is opt-in");
    let said = run(&["--flipbook"]);
    assert!(said.contains("-flipbook.png"), "{said}");
    assert_eq!(apng_frames(&out.join("sim-flipbook.png")), 8);
}
