//! The camera's optics: the pixel kernel (PSF and footprint), the supersampled footprint film
//! against closed forms, point sampling kept bit for bit in datasets, and the scene fields.

mod support;

use heatsim::camera::{rasterize, Camera, Footprint, PixelKernel};
use heatsim::scene::camera::CameraSpec;

/// Standard normal distribution Φ(z).
fn phi_cdf(z: f64) -> f64 {
    0.5 * (1.0 + libm::erf(z / std::f64::consts::SQRT_2))
}

/// Standard normal density φ(z).
fn phi_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

mod kernel {
    use super::*;

    #[test]
    fn weights_sum_to_one_and_a_uniform_field_is_unchanged() {
        for (s, sigma) in [(1, None), (4, None), (1, Some(0.35)), (4, Some(0.35)), (7, Some(1.3)), (16, Some(0.35))] {
            let k = PixelKernel::new(s, sigma).unwrap();
            let sum: f64 = k.weights().iter().sum();
            assert!((sum - 1.0).abs() < 1e-14, "s {s}, sigma {sigma:?}: sum {sum}");
            assert!(k.weights().iter().all(|&c| c >= 0.0));
            let (w, h) = (9, 5);
            let fw = s * (w + 2 * k.margin());
            let fine = vec![301.25_f64.powi(4); fw * s * (h + 2 * k.margin())];
            let mut out = vec![0.0; w * h];
            k.integrate(&fine, fw, w, h, &mut out);
            for &x in &out {
                assert!((x / 301.25_f64.powi(4) - 1.0).abs() < 1e-14, "s {s}, sigma {sigma:?}: {x}");
            }
        }
        // Without a PSF the kernel is the pixel's box: 1/s on its own s sub-samples.
        let k = PixelKernel::new(4, None).unwrap();
        assert_eq!((k.reach(), k.margin(), k.weights()), (0, 0, &[0.25; 4][..]));
    }

    /// A radiance step across a sub-sample boundary at pixel coordinate `x0`, blurred by a
    /// Gaussian of sigma (pixels) and integrated over each pixel [u - 1/2, u + 1/2]:
    /// `∫ Φ((x - x0)/σ) dx = σ [G((u + 1/2 - x0)/σ) - G((u - 1/2 - x0)/σ)]`,
    /// `G(z) = z Φ(z) + φ(z)`. The kernel's only approximation for this image (constant per
    /// sub-sample cell) is the midpoint rule over the pixel's s sub-samples, whose error is at
    /// most `h^2 / 24 max|f''|` with `h = 1/s` and `max|f''| = φ(1)/σ^2 < 0.25/σ^2`; the
    /// truncation at 4 σ adds at most 1e-4.
    #[test]
    fn gaussian_psf_gives_the_error_function_edge_profile() {
        let g = |z: f64| z * phi_cdf(z) + phi_pdf(z);
        for (s, sigma) in [(8, 0.35), (16, 0.35), (8, 1.0), (16, 2.5)] {
            let k = PixelKernel::new(s, Some(sigma)).unwrap();
            let (w, h, m) = (24, 3, k.margin());
            let fw = s * (w + 2 * m);
            let fh = s * (h + 2 * m);
            // The step starts at fine column c0: pixel coordinate (c0 + 1/2)/s - 1/2 - m of its
            // centre, minus half a sub-sample.
            let c0 = s * (11 + m) + 3;
            let x0 = c0 as f64 / s as f64 - 0.5 - m as f64;
            let fine: Vec<f64> = (0..fw * fh).map(|i| if i % fw >= c0 { 1.0 } else { 0.0 }).collect();
            let mut out = vec![0.0; w * h];
            k.integrate(&fine, fw, w, h, &mut out);
            let tol = 0.25 / (24.0 * (s * s) as f64 * sigma * sigma) + 1e-4;
            let mut worst = 0.0_f64;
            for v in 0..h {
                for u in 0..w {
                    let uf = u as f64;
                    let want = sigma * (g((uf + 0.5 - x0) / sigma) - g((uf - 0.5 - x0) / sigma));
                    worst = worst.max((out[v * w + u] - want).abs());
                }
            }
            assert!(worst < tol, "s {s}, sigma {sigma}: error {worst:e} > {tol:e}");
            // The edge is visibly blurred: the pixel one past the edge pixel is neither 0 nor 1.
            assert!(out[12] < 1.0 - 1e-4 && out[10] > 1e-4, "s {s}, sigma {sigma}: {:?}", &out[8..15]);
        }
        // Without the PSF the same image gives the box average only: the test above fails.
        let k = PixelKernel::new(8, None).unwrap();
        let (w, fw) = (24, 8 * 24);
        let fine: Vec<f64> = (0..fw * 8).map(|i| if i % fw >= 8 * 11 + 3 { 1.0 } else { 0.0 }).collect();
        let mut out = vec![0.0; w];
        k.integrate(&fine, fw, w, 1, &mut out);
        assert_eq!((out[10], out[11], out[12]), (0.0, 5.0 / 8.0, 1.0));
    }

    #[test]
    fn bad_kernel_parameters_name_the_field() {
        let field = |r: Result<PixelKernel, heatsim::camera::CameraError>| match r {
            Err(heatsim::camera::CameraError::Invalid { field, .. }) => field,
            other => panic!("expected an error, got {other:?}"),
        };
        assert_eq!(field(PixelKernel::new(0, None)), "camera.supersampling");
        assert_eq!(field(PixelKernel::new(2, Some(-1.0))), "camera.psf.sigma");
        assert_eq!(field(PixelKernel::new(2, Some(f64::NAN))), "camera.psf.sigma");
    }
}

mod footprint {
    use super::*;

    const T_OBJECT: f64 = 320.0;
    const T_BACKGROUND: f64 = 295.0;

    /// A 16 x 12 camera looking down -z at the plane z = 0 (depth 0.3683 m).
    fn small_camera() -> Camera {
        let spec = CameraSpec { width: 16, height: 12, hfov_deg: 8.0, ..CameraSpec::default() };
        Camera::from_spec(&spec).unwrap()
    }

    /// A plate in z = 0 whose image is the half-plane right of the line
    /// `u = u0 + slope (v - v0)` (pixel coordinates), out to `u_right`.
    fn half_plane(camera: &Camera, u0: f64, v0: f64, slope: f64, u_right: f64) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let depth = camera.to_camera([0.0, 0.0, 0.0])[2];
        let edge = |v: f64| u0 + slope * (v - v0);
        let (top, bottom) = (-4.0, f64::from(camera.height) + 3.0);
        let verts = vec![
            camera.unproject(edge(top), top, depth),
            camera.unproject(u_right, top, depth),
            camera.unproject(u_right, bottom, depth),
            camera.unproject(edge(bottom), bottom, depth),
        ];
        (verts, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// The covered fraction a pixel's film implies: `(T_eq^4 - T_b^4) / (T_o^4 - T_b^4)`.
    fn fraction(t_eq: f64) -> f64 {
        (t_eq.powi(4) - T_BACKGROUND.powi(4)) / (T_OBJECT.powi(4) - T_BACKGROUND.powi(4))
    }

    fn film(camera: &Camera, kernel: PixelKernel, verts: &[[f64; 3]], tris: &[[usize; 3]]) -> (Vec<f64>, Footprint) {
        let mask = rasterize(camera, verts, tris).mask();
        let fp = Footprint::new(camera, kernel, verts, tris);
        let mut out = vec![0.0; camera.pixel_count()];
        fp.film_into(tris, &vec![T_OBJECT; verts.len()], T_BACKGROUND, &mask, &mut out);
        (out, fp)
    }

    /// A straight edge of slope 0.3 crossing a pixel: the pixel's radiance is the mix
    /// `a T_o^4 + (1 - a) T_b^4` with `a` its area right of the line; where the line crosses
    /// the pixel's top and bottom sides, `a = u + 1/2 - u_edge(v)` exactly. A regular s x s
    /// grid miscounts at most one sub-sample per sub-sample row: error <= 1/s.
    #[test]
    fn a_straight_edge_mixes_radiance_by_covered_area() {
        let camera = small_camera();
        let (u0, v0, slope) = (6.3, 5.0, 0.3);
        let (verts, tris) = half_plane(&camera, u0, v0, slope, 40.0);
        let mut errors = Vec::new();
        for s in [1, 2, 4, 8, 16] {
            let (out, fp) = film(&camera, PixelKernel::new(s, None).unwrap(), &verts, &tris);
            let mut worst = 0.0_f64;
            let mut edge_pixels = 0;
            for v in 0..12 {
                let (vf, w) = (v as f64, 16usize);
                let (top, bottom) = (u0 + slope * (vf - 0.5 - v0), u0 + slope * (vf + 0.5 - v0));
                for u in 0..w {
                    let uf = u as f64;
                    let t = out[v * w + u];
                    if top.max(bottom) < uf - 0.5 {
                        assert!((t - T_OBJECT).abs() < 1e-9, "s {s}: inside pixel ({u}, {v}) = {t}");
                    } else if top.min(bottom) > uf + 0.5 {
                        assert!(t.is_nan(), "s {s}: background pixel ({u}, {v}) = {t}");
                    } else if top.min(bottom) > uf - 0.5 && top.max(bottom) < uf + 0.5 {
                        let a = uf + 0.5 - u0 - slope * (vf - v0);
                        let got = if t.is_nan() { 0.0 } else { fraction(t) };
                        assert!((got - fp.coverage()[v * w + u]).abs() < 1e-12);
                        worst = worst.max((got - a).abs());
                        edge_pixels += 1;
                    }
                }
            }
            assert!(edge_pixels >= 8, "{edge_pixels} edge pixels with a closed form");
            assert!(worst <= 1.0 / s as f64 + 1e-12, "s {s}: error {worst} > 1/s");
            errors.push(worst);
        }
        eprintln!("largest coverage error at s = 1, 2, 4, 8, 16: {errors:?}");
        // Converges: point sampling is off by up to a half, s = 16 by a few hundredths.
        assert!(errors[0] > 0.3 && errors[4] < 0.04 && errors[4] < errors[2] && errors[2] < errors[1]);
    }

    /// The PSF moves radiance but keeps all of it (its kernel sums to 1 and the supersampled
    /// image extends by its reach): for a plate inside the image, the total excess radiance
    /// `Σ (T_eq^4 - T_b^4)` is the same with and without blur, and blurred radiance reaches
    /// pixels outside the silhouette (finite, above T_b), but no pixel beyond the reach.
    #[test]
    fn psf_spreads_radiance_beyond_the_mask_and_keeps_it() {
        let camera = small_camera();
        // A quadrilateral plate well inside the image: columns 6.0 to 9.7, rows 3.4 to 8.6.
        let tris = [[0, 1, 2], [0, 2, 3]];
        let depth = camera.to_camera([0.0, 0.0, 0.0])[2];
        let verts: Vec<[f64; 3]> = [(6.0, 3.4), (9.7, 3.4), (9.7, 8.6), (7.56, 8.6)]
            .iter()
            .map(|&(u, v)| camera.unproject(u, v, depth))
            .collect();
        let mask = rasterize(&camera, &verts, &tris).mask();
        let excess =
            |out: &[f64]| -> f64 { out.iter().filter(|t| !t.is_nan()).map(|t| t.powi(4) - T_BACKGROUND.powi(4)).sum() };
        let (sharp, _) = film(&camera, PixelKernel::new(8, None).unwrap(), &verts, &tris);
        let sigma = 0.6;
        let (blurred, fp) = film(&camera, PixelKernel::new(8, Some(sigma)).unwrap(), &verts, &tris);
        let (e0, e1) = (excess(&sharp), excess(&blurred));
        assert!((e1 / e0 - 1.0).abs() < 1e-12, "excess radiance {e0} without blur, {e1} with");
        // Pixels one step outside the silhouette get some radiance; those beyond the reach none.
        let reach = fp.kernel().reach() as f64 / 8.0 + 0.5;
        let mut outside_lit = 0;
        for v in 0..12 {
            for u in 0..16 {
                let (t, p) = (blurred[v * 16 + u], v * 16 + u);
                let (uf, vf) = (u as f64, v as f64);
                let far = uf < 6.0 - reach - 1.0 || uf > 9.7 + reach || vf < 3.4 - reach || vf > 8.6 + reach;
                if far {
                    assert!(t.is_nan(), "pixel ({u}, {v}) beyond the PSF's reach = {t}");
                } else if !mask[p] && sharp[p].is_nan() && !t.is_nan() {
                    assert!(t > T_BACKGROUND && t < T_OBJECT);
                    outside_lit += 1;
                }
            }
        }
        assert!(outside_lit >= 10, "only {outside_lit} pixels outside the silhouette receive blurred radiance");
        // Blur lowers the brightest pixel, which the sharp film shows at T_o.
        let max = |x: &[f64]| x.iter().copied().filter(|t| !t.is_nan()).fold(0.0, f64::max);
        assert!((max(&sharp) - T_OBJECT).abs() < 1e-9 && max(&blurred) < T_OBJECT - 0.1);
    }

    #[test]
    fn the_supersampled_camera_puts_sub_samples_where_documented() {
        let camera = small_camera();
        for (s, m) in [(1, 0), (3, 1), (4, 2)] {
            let fine = heatsim::camera::supersampled_camera(&camera, s, m);
            assert_eq!((fine.width, fine.height), ((s * (16 + 2 * m)) as u32, (s * (12 + 2 * m)) as u32));
            let p = camera.unproject(5.3, 7.9, 0.4);
            let [u, v] = camera.project(p).unwrap();
            let [uu, vv] = fine.project(p).unwrap();
            let sf = s as f64;
            assert!(((uu + 0.5) / sf - 0.5 - m as f64 - u).abs() < 1e-9);
            assert!(((vv + 0.5) / sf - 0.5 - m as f64 - v).abs() < 1e-9);
        }
    }
}

mod dataset {
    use super::*;
    use heatsim::scene::Scene;
    use heatsim::simulate::{simulate_volumetric, Simulation};

    /// A 3 x 2 x 0.5 cm PLA box under a uniform lamp, 3 frames, filmed by a 64 x 48 camera.
    fn scene(camera_extra: &str) -> Scene {
        let text = format!(
            r#"{{
            "object": {{ "kind": "cuboid", "width": 0.03, "height": 0.02, "thickness": 0.005 }},
            "material": {{ "name": "pla" }},
            "lamps": [ {{ "kind": "uniform", "flux": 2000 }} ],
            "camera": {{ "width": 64, "height": 48, "hfov_deg": 8, "look_at": [0.015, 0.01, 0],
                         "position": [0.015, 0.01, 0.3683], "netd": 0.05 {camera_extra} }},
            "timing": {{ "duration": 1.0, "time_step": 0.5, "frame_interval": 0.5, "pre_heating_frames": 1 }}
        }}"#
        );
        Scene::from_json_str(&text, std::path::Path::new(".")).unwrap()
    }

    fn simulate(scene: &Scene) -> (heatsim::mesh::tetmesh::TetMesh, Simulation) {
        let mesh = support::box_mesh(6, 4, 2, 0.03, 0.02, 0.005);
        let sim = simulate_volumetric(scene, &mesh, |_, _| {}).unwrap();
        (mesh, sim)
    }

    fn bits32(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn point_sampling_films_the_pixel_centres_bit_for_bit() {
        let default = scene("");
        let explicit = scene(r#", "supersampling": 1, "psf": { "kind": "none" }"#);
        assert_eq!(default, explicit);
        // Point sampling adds no key to the scene as written (meta.json, cache keys).
        let json = serde_json::to_string(&explicit.camera).unwrap();
        assert!(!json.contains("supersampling") && !json.contains("psf"), "{json}");
        let (mesh, sim) = simulate(&default);
        let a = heatsim::dataset::render(&default, &mesh.verts, &mesh.boundary, &sim).unwrap();
        let b = heatsim::dataset::render(&explicit, &mesh.verts, &mesh.boundary, &sim).unwrap();
        assert_eq!(bits32(&a.film), bits32(&b.film));
        assert_eq!(bits32(&a.video), bits32(&b.video));
        assert_eq!(a.object_sub_samples, 0);
        // ... and the film is the pixel-centre gather, the video its exposure.
        let camera = Camera::from_spec(&default.camera).unwrap();
        let render = rasterize(&camera, &mesh.verts, &mesh.boundary);
        let n = camera.pixel_count();
        for k in 0..sim.times.len() {
            let mut centre = vec![0.0_f32; n];
            render.interpolate(&mesh.boundary, sim.frame(k), &mut centre);
            assert_eq!(bits32(&a.film[k * n..(k + 1) * n]), bits32(&centre), "frame {k}");
        }
        let emissivity = default.material.resolve().unwrap().emissivity;
        let ambient = default.environment.ambient_temperature;
        let sensor = heatsim::camera::Sensor::from_spec(&default.camera, emissivity, ambient).unwrap();
        assert_eq!(bits32(&heatsim::dataset::expose_video(&sensor, &a.film, &a.mask)), bits32(&a.video));
    }

    #[test]
    fn optics_blur_the_film_but_keep_the_ground_truth() {
        let sharp = scene("");
        let optical = scene(r#", "supersampling": 3, "psf": { "kind": "gaussian", "sigma": 1.2e-5 }"#);
        let (mesh, sim) = simulate(&sharp);
        let a = heatsim::dataset::render(&sharp, &mesh.verts, &mesh.boundary, &sim).unwrap();
        let b = heatsim::dataset::render(&optical, &mesh.verts, &mesh.boundary, &sim).unwrap();
        // Ground truth at pixel centres is unchanged.
        assert_eq!(a.mask, b.mask);
        assert_eq!(bits32(&a.depth), bits32(&b.depth));
        assert_eq!(bits32(&a.flux), bits32(&b.flux));
        assert!(b.object_sub_samples > 8 * a.mask.iter().filter(|&&m| m).count());
        // The film is finite on every masked pixel and also just outside; the last frame's
        // interior stays within a few mK of the sharp film (the box heats uniformly), the
        // silhouette pixels drop towards the background.
        let n = a.pixels();
        let last = (sim.times.len() - 1) * n;
        let (fa, fb) = (&a.film[last..], &b.film[last..]);
        let outside = (0..n).filter(|&p| !a.mask[p] && fb[p].is_finite()).count();
        assert!(outside > 20, "{outside} pixels outside the mask receive radiance");
        let ambient = sharp.environment.ambient_temperature as f32;
        let hottest = fa.iter().copied().filter(|t| t.is_finite()).fold(0.0, f32::max);
        let mut differ = 0;
        for p in (0..n).filter(|&p| a.mask[p]) {
            assert!(fb[p].is_finite() && fb[p] <= hottest + 1e-3 && fb[p] >= ambient - 1e-3, "pixel {p}");
            differ += usize::from(fa[p] - fb[p] > 0.05);
        }
        assert!(differ > 20, "only {differ} silhouette pixels darkened by the blur");
        // The video is finite everywhere (background is T_refl plus noise).
        assert!(b.video.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn camera_json_records_the_optics_only_when_there_are_some() {
        use heatsim::dataset_format::{read_camera, to_json_text, CameraFile, CAMERA_FILE};
        let dir = tempfile::tempdir().unwrap();
        for (extra, has_optics) in [("", false), (r#", "supersampling": 2, "psf": { "kind": "gaussian" }"#, true)] {
            let scene = scene(extra);
            let camera = Camera::from_spec(&scene.camera).unwrap();
            let file = CameraFile::new(&camera, &scene.camera, scene.timing.frame_interval);
            let text = to_json_text(&file);
            assert_eq!(text.contains("supersampling") || text.contains("psf"), has_optics, "{text}");
            std::fs::write(dir.path().join(CAMERA_FILE), &text).unwrap();
            let back = read_camera(dir.path()).unwrap();
            assert_eq!(back, file);
            if has_optics {
                assert_eq!(back.supersampling, Some(2));
                assert_eq!(back.psf, Some(scene.camera.psf.clone()));
            }
        }
        // A file with bad optics is refused naming the key.
        let bad = to_json_text(&CameraFile {
            supersampling: Some(0),
            ..CameraFile::new(&Camera::from_spec(&CameraSpec::default()).unwrap(), &CameraSpec::default(), 0.1)
        });
        std::fs::write(dir.path().join(CAMERA_FILE), bad).unwrap();
        let e = read_camera(dir.path()).unwrap_err().to_string();
        assert!(e.contains("supersampling: must be >= 1, got 0"), "{e}");
    }

    #[test]
    fn optics_need_triangles_not_the_camera_grid() {
        let text = r#"{ "object": { "kind": "cuboid", "width": 0.03, "height": 0.02, "thickness": 0.005 },
            "material": { "name": "pla" }, "solver": { "kind": "surface", "surface_mesh": "camera_grid" },
            "camera": { "psf": { "kind": "gaussian" } } }"#;
        let e = Scene::from_json_str(text, std::path::Path::new(".")).unwrap_err().to_string();
        assert!(e.starts_with("camera.psf: must be point sampling"), "{e}");
    }
}

mod scene_fields {
    use heatsim::scene::camera::{PsfSpec, BOSON_PSF_SIGMA};
    use heatsim::scene::Scene;

    fn camera(fields: &str) -> Result<Scene, String> {
        let text = format!(
            r#"{{ "object": {{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": 0.01 }},
                 "material": {{ "name": "pla" }}, "camera": {{ {fields} }} }}"#
        );
        Scene::from_json_str(&text, std::path::Path::new(".")).map_err(|e| e.to_string())
    }

    #[test]
    fn defaults_and_round_trip() {
        let s = camera("").unwrap().camera;
        assert_eq!((s.supersampling, s.point_sampling()), (1, true));
        let s = camera(r#""supersampling": 4, "psf": { "kind": "gaussian" }"#).unwrap().camera;
        match &s.psf {
            PsfSpec::Gaussian(g) => assert_eq!(g.sigma, BOSON_PSF_SIGMA),
            other => panic!("{other:?}"),
        }
        // 0.42 lambda N with lambda = 10 um, N = 1.0.
        assert!((BOSON_PSF_SIGMA - 0.42 * 10e-6 * 1.0).abs() < 1e-18);
        let json = serde_json::to_string(&s).unwrap();
        assert!(
            json.contains(r#""supersampling":4"#) && json.contains(r#""psf":{"kind":"gaussian","sigma":4.2e-6}"#),
            "{json}"
        );
        let back: heatsim::scene::CameraSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn bad_optics_are_refused_naming_the_field() {
        for (fields, want) in [
            (r#""supersampling": 0"#, "camera.supersampling: must be >= 1, got 0"),
            (r#""supersampling": 17"#, "camera.supersampling: must be <= 16, got 17"),
            (r#""psf": { "kind": "gaussian", "sigma": -1e-6 }"#, "camera.psf.sigma: must be > 0 m, got -1e-6"),
            (r#""psf": { "kind": "gaussian", "sigma": 0 }"#, "camera.psf.sigma: must be > 0 m, got 0"),
            (r#""psf": { "kind": "gaussian", "sigma": 0.001 }"#, "camera.psf.sigma: must be <= 9.6e-5 m, got 0.001"),
            (r#""psf": { "kind": "gaussian", "sgima": 1e-6 }"#, "camera.psf.sgima: unknown field `sgima`"),
            (r#""psf": { "kind": "none", "sigma": 1e-6 }"#, "camera.psf.sigma: unknown field `sigma`"),
            (r#""psf": { "kind": "airy" }"#, "camera.psf.kind"),
            (r#""supersampling": 2.5"#, "camera.supersampling"),
        ] {
            let e = camera(fields).expect_err(fields);
            assert!(e.starts_with(want), "{fields}: got {e:?}, want {want:?}");
        }
    }
}
