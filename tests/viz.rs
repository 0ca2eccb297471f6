//! Software renders, picture helpers and plots. Set ANISOCB_SAVE_PICTURES=DIR to write the
//! pictures these tests draw as PNG files for a look (needs the default `cli` feature).

use anisocb::geom::GridMesh;
use anisocb::viz::heat::{colorbar, ScalarColors};
use anisocb::viz::image::{hstack, image_rgb8, resize_nearest, upscale_nearest, vstack, Rgb8, WHITE};
use anisocb::viz::plot::{format_number, LinePlot};
use anisocb::viz::render::{render_mesh, render_row, Camera, Shading, Tile, View};
use anisocb::Tensor;

fn save(name: &str, img: &Rgb8) {
    #[cfg(feature = "cli")]
    if let Ok(dir) = std::env::var("ANISOCB_SAVE_PICTURES") {
        let path = std::path::Path::new(&dir).join(name);
        anisocb::app::ui::save_png(&path, img).unwrap();
    }
    #[cfg(not(feature = "cli"))]
    let _ = (name, img);
}

/// A hanging cloth with wrinkles and a fold towards the bottom (so both sides show).
fn cloth(w: usize, h: usize, amp: f32) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.0, 1.0);
    for p in &mut m.pos {
        let (x, y) = (p[0], p[1]);
        let hang = 1.0 - y;
        p[2] = amp * (14.0 * x).sin() * hang + 0.25 * hang * hang;
        p[1] = y - 0.15 * hang * hang + 0.02 * (9.0 * x).cos() * hang;
    }
    m
}

fn cloth_pixels(img: &Rgb8) -> usize {
    // The default cloth colours are saturated (orange front, blue back); the background is grey.
    (0..img.w * img.h)
        .filter(|&p| {
            let c = &img.data[3 * p..3 * p + 3];
            let (lo, hi) = (c.iter().min().unwrap(), c.iter().max().unwrap());
            hi - lo > 30
        })
        .count()
}

#[test]
fn flat_sheet_covers_the_expected_silhouette() {
    // A 1 × 1 m sheet seen head-on (orthographic, 10% margin) fills the middle 80% × 80%.
    let m = GridMesh::flat(9, 9, 1.0, 1.0);
    let view = View { azimuth_deg: 0.0, elevation_deg: 0.0, fov_deg: 0.0, margin: 0.1 };
    let cam = Camera::fit_meshes(&view, &[&m], 120, 120).unwrap();
    let img = render_mesh(&m, &cam, &Shading::default(), None).unwrap();
    let cover = cloth_pixels(&img) as f32 / (120.0 * 120.0);
    assert!((cover - 0.64).abs() < 0.02, "coverage {cover}");
    // Front side faces the camera: orange (red > blue) in the middle.
    let c = img.get(60, 60);
    assert!(c[0] > c[2] + 40, "front colour {c:?}");
    // Seen from behind, the other side's tint shows: still lit (two-sided), blue > red.
    let back = View { azimuth_deg: 180.0, ..view };
    let cam = Camera::fit_meshes(&back, &[&m], 120, 120).unwrap();
    let img = render_mesh(&m, &cam, &Shading::default(), None).unwrap();
    let c = img.get(60, 60);
    assert!(c[2] > c[0] + 40 && c[2] > 100, "back colour {c:?}");
    save("flat_front_back.png", &img);
}

#[test]
fn perspective_view_and_shared_camera_render_a_comparison_row() {
    let lr = cloth(16, 16, 0.0);
    let hr = cloth(64, 64, 0.03);
    let err: Vec<f32> = hr.pos.iter().map(|p| (p[2] - 0.125).abs()).collect();
    let tiles = [
        Tile { mesh: &lr, label: "LR", colors: None },
        Tile { mesh: &lr, label: "bicubic", colors: None },
        Tile { mesh: &hr, label: "anisocb", colors: None },
        Tile { mesh: &hr, label: "HR", colors: None },
        Tile { mesh: &hr, label: "error", colors: Some(ScalarColors { values: &err, lo: 0.0, hi: 0.2 }) },
    ];
    let row = render_row(&tiles, &View::default(), &Shading::default(), 200, 200, 4).unwrap();
    assert_eq!((row.w, row.h), (5 * 200 + 4 * 4, 200));
    for k in 0..5 {
        let tile = Rgb8 { w: 200, h: 200, data: crop(&row, k * 204, 200) };
        let n = cloth_pixels(&tile);
        assert!(n > 200 * 200 / 8, "tile {k} shows {n} cloth pixels");
    }
    let bar = colorbar(200, 0.0, 0.2, "err m");
    let persp = View { fov_deg: 35.0, ..View::default() };
    let cam = Camera::fit_meshes(&persp, &[&hr], 200, 200).unwrap();
    let p = render_mesh(&hr, &cam, &Shading::default(), None).unwrap();
    assert!(cloth_pixels(&p) > 200 * 200 / 8);
    save("row.png", &hstack(&[row, bar, p], 4, WHITE));
    // Deterministic.
    let again = render_mesh(&hr, &cam, &Shading::default(), None).unwrap();
    assert_eq!(again, render_mesh(&hr, &cam, &Shading::default(), None).unwrap());
    assert!(render_mesh(
        &hr,
        &cam,
        &Shading::default(),
        Some(ScalarColors { values: &[0.0], lo: 0.0, hi: 1.0 })
    )
    .is_err());
}

fn crop(img: &Rgb8, x0: usize, w: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(w * img.h * 3);
    for y in 0..img.h {
        out.extend_from_slice(&img.data[3 * (y * img.w + x0)..3 * (y * img.w + x0 + w)]);
    }
    out
}

#[test]
fn geometry_images_and_maps_become_pixels() {
    let t = Tensor::from_vec(&[3, 1, 2], vec![0.0, 1.0, 0.5, 2.0, -1.0, 0.25]).unwrap();
    let img = image_rgb8(&t).unwrap();
    assert_eq!((img.w, img.h), (2, 1));
    assert_eq!(img.get(0, 0), [0, 128, 0]);
    assert_eq!(img.get(1, 0), [255, 255, 64]);
    let map = Tensor::from_vec(&[1, 1, 2, 2], vec![0.0, 1.0, 0.5, 0.0]).unwrap();
    let g = image_rgb8(&map).unwrap();
    assert_eq!(g.get(1, 0), [255, 255, 255]);
    assert_eq!(g.get(0, 1), [128, 128, 128]);
    assert!(image_rgb8(&Tensor::zeros(&[2, 4, 4])).is_err());
    let up = upscale_nearest(&g, 3);
    assert_eq!((up.w, up.h), (6, 6));
    assert_eq!(up.get(5, 0), [255, 255, 255]);
    assert_eq!(up.get(2, 3), [128, 128, 128]);
    assert_eq!(resize_nearest(&g, 4, 4), upscale_nearest(&g, 2));
    let s = vstack(&[hstack(&[g.clone(), up.clone()], 2, WHITE), g], 1, WHITE);
    assert_eq!((s.w, s.h), (2 + 2 + 6, 6 + 1 + 2));
}

#[test]
fn labels_draw_with_the_bitmap_font() {
    let mut img = Rgb8::new(120, 20, [200, 200, 200]);
    img.label("anisocb 0123", 1);
    let dark = img.data.chunks(3).filter(|c| c[0] < 50).count();
    assert!(dark > 40, "{dark} text pixels");
    let mut big = Rgb8::new(400, 60, WHITE);
    big.text(4, 4, "ABCDEFGHIJKLMNOPQRSTUVWXYZ", 2, [0, 0, 0]);
    big.text(4, 22, "abcdefghijklmnopqrstuvwxyz", 2, [0, 0, 0]);
    big.text(4, 40, "0123456789 .,:-+=/%()_# frame 12", 2, [0, 0, 0]);
    save("font.png", &big);
}

#[test]
fn line_plot_draws_series_legend_and_log_axis() {
    assert_eq!(format_number(0.25), "0.25");
    assert_eq!(format_number(1500.0), "1500");
    assert_eq!(format_number(1e-4), "1e-4");
    assert_eq!(format_number(-2.0), "-2");
    let loss: Vec<f32> = (0..200).map(|i| 0.5 * (-(i as f32) / 40.0).exp() + 1e-3).collect();
    let val: Vec<f32> = (0..200).map(|i| 0.6 * (-(i as f32) / 50.0).exp() + 2e-3).collect();
    let p = LinePlot::new("training loss")
        .labels("step", "MSE")
        .log_y(true)
        .series_y("train", &loss)
        .series_y("validation", &val);
    let img = p.render(480, 300).unwrap();
    let has = |c: [u8; 3]| img.data.chunks(3).any(|px| px == c);
    assert!(has(anisocb::viz::plot::PALETTE[0]) && has(anisocb::viz::plot::PALETTE[1]));
    let lin = LinePlot::new("per-frame RMSE")
        .labels("frame", "m")
        .series_y("bicubic", &[0.02, 0.025, f32::NAN, 0.03, 0.028])
        .series_y("anisocb", &[0.01, 0.012, 0.011, 0.015, 0.013])
        .render(320, 200)
        .unwrap();
    save("plots.png", &vstack(&[img, lin], 4, WHITE));
    assert!(LinePlot::new("x").render(10, 10).is_err());
    // Empty and constant series do not fail.
    LinePlot::new("empty").render(200, 150).unwrap();
    LinePlot::new("const").series_y("c", &[1.0, 1.0]).log_y(true).render(200, 150).unwrap();
}

#[test]
fn sphere_prop_renders_as_a_disc_and_hides_cloth_behind_it() {
    use anisocb::viz::render::{render_layers, sphere_mesh, Layer};
    // Radius 0.5 m in a 1 m box, head-on, 10% margin on 100 px: a disc of 40 px radius.
    let s = sphere_mesh([0.0, 0.0, 0.0], 0.5, 32);
    let view = View { azimuth_deg: 0.0, elevation_deg: 0.0, fov_deg: 0.0, margin: 0.1 };
    let cam = Camera::fit_meshes(&view, &[&s], 100, 100).unwrap();
    let red = Layer { tris: None, mesh: &s, colors: None, tint: Some([1.0, 0.0, 0.0]) };
    let img = render_layers(&[red], &cam, &Shading::default()).unwrap();
    let cover = cloth_pixels(&img) as f32 / 1e4;
    let want = std::f32::consts::PI * 0.4 * 0.4;
    assert!((cover - want).abs() < 0.02, "coverage {cover} vs {want}");
    // A sheet behind the sphere (z = −0.6) shows only around it; in front (z = +0.6) covers it.
    let mut sheet = GridMesh::flat(5, 5, 1.0, 1.0);
    for p in &mut sheet.pos {
        *p = [p[0] - 0.5, p[1] - 0.5, -0.6];
    }
    let blue = Layer { tris: None, mesh: &sheet, colors: None, tint: Some([0.0, 0.0, 1.0]) };
    let img = render_layers(&[blue, red], &cam, &Shading::default()).unwrap();
    let c = img.get(50, 50);
    assert!(c[0] > c[2], "sphere in front: {c:?}");
    for p in &mut sheet.pos {
        p[2] = 0.6;
    }
    let blue = Layer { tris: None, mesh: &sheet, colors: None, tint: Some([0.0, 0.0, 1.0]) };
    let img = render_layers(&[red, blue], &cam, &Shading::default()).unwrap();
    let c = img.get(50, 50);
    assert!(c[2] > c[0], "sheet in front: {c:?}");
}
