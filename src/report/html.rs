//! The HTML report, one self-contained file (images embedded as data URIs, plots as inline
//! SVG): photo | synthetic | model error with its colour bar, the parameter table, the
//! convergence of every group, the textures.

use super::Results;
use crate::fit::params::Value;
use base64::Engine;
use std::path::Path;

/// The file `rel` (relative to `dir`) as a data URI, or the relative link where it cannot be
/// read (the page then still works next to its files).
fn embedded(dir: &Path, rel: &str) -> String {
    match std::fs::read(dir.join(rel)) {
        Ok(bytes) => format!(
            "data:image/png;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(bytes)
        ),
        Err(_) => esc(rel),
    }
}

/// The error picture's colour bar: `super::false_colour`'s ramp (its stops as the PNG shows
/// them), from 0 to `scale` and beyond.
fn colour_bar(scale: f32) -> String {
    let stops = [
        (0.0, [0.0, 0.0, 0.0]),
        (0.2, [0.0, 0.05, 0.6]),
        (0.4, [0.0, 0.6, 0.1]),
        (0.6, [0.9, 0.85, 0.0]),
        (0.8, [0.9, 0.05, 0.0]),
        (1.0, [1.0, 1.0, 1.0]),
    ];
    let grad: String = stops
        .iter()
        .map(|(o, [r, g, b])| {
            format!(
                "<stop offset=\"{o}\" stop-color=\"rgb({},{},{})\"/>",
                (r * 255.0f32).round(),
                (g * 255.0f32).round(),
                (b * 255.0f32).round()
            )
        })
        .collect();
    let ticks: String = (0..=4)
        .map(|k| {
            let x = 24.0 + 300.0 * k as f32 / 4.0;
            let v = 100.0 * scale * k as f32 / 4.0;
            let label = if k == 4 {
                format!("≥ {v:.1}%")
            } else {
                format!("{v:.1}%")
            };
            format!(
                "<line x1=\"{x}\" y1=\"26\" x2=\"{x}\" y2=\"31\" stroke=\"black\"/><text x=\"{x}\" y=\"44\" font-size=\"11\" text-anchor=\"middle\">{}</text>",
                esc(&label)
            )
        })
        .collect();
    format!(
        "<svg id=\"colour-bar\" width=\"360\" height=\"50\" xmlns=\"http://www.w3.org/2000/svg\"><defs><linearGradient id=\"ramp\">{grad}</linearGradient></defs><rect x=\"24\" y=\"6\" width=\"300\" height=\"20\" fill=\"url(#ramp)\" stroke=\"#888\"/>{ticks}</svg>"
    )
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn value(v: &Value) -> String {
    match v {
        Value::Rgb([r, g, b]) => format!("({r:.4}, {g:.4}, {b:.4})"),
        Value::Scalar(x) => format!("{x:.4}"),
    }
}

/// A 1σ as the page shows it: "not determined" where results.json has null.
fn sigma(s: &super::Sigma) -> String {
    let one = |x: &Option<f32>| x.map_or("not determined".to_string(), |x| format!("{x:.4}"));
    match s {
        super::Sigma::Rgb(c) if c.iter().all(Option::is_none) => "not determined".into(),
        super::Sigma::Rgb([r, g, b]) => format!("({}, {}, {})", one(r), one(g), one(b)),
        super::Sigma::Scalar(x) => one(x),
    }
}

/// The page for the recovery whose outputs are in `dir`, with each group's convergence plot
/// (`plots`: group, SVG) and the error picture's full scale.
pub fn report(res: &Results, dir: &Path, plots: &[(String, String)], scale: f32) -> String {
    let mut rows = String::new();
    for g in &res.groups {
        let params: Vec<String> = g
            .params
            .iter()
            .map(|(k, v)| match g.sigma.get(k) {
                Some(sd) => format!("{k} = {} ± {}", value(v), sigma(sd)),
                None => format!("{k} = {}", value(v)),
            })
            .collect();
        let albedo = g.albedo.as_ref().map_or("–".to_string(), |a| {
            format!(
                "0°: {} ± {}; 60°: {} ± {}",
                value(&Value::Rgb(a.normal)),
                sigma(&super::Sigma::Rgb(a.sigma_normal)),
                value(&Value::Rgb(a.at_60deg)),
                sigma(&super::Sigma::Rgb(a.sigma_60deg))
            )
        });
        let pct = |x: Option<f32>| x.map_or("–".to_string(), |e| format!("{:.2}%", 100.0 * e));
        rows += &format!(
            "<tr><td>{}</td><td>{} ({})</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            esc(&g.name),
            g.level,
            g.level_number,
            g.status,
            pct(g.error),
            pct(g.noise_floor),
            g.usable_pixels,
            esc(&params.join(", ")),
            esc(&albedo),
            esc(g.note.as_deref().unwrap_or(""))
        );
    }
    let mut textures = String::new();
    for (g, t) in res
        .groups
        .iter()
        .filter_map(|g| g.texture.as_ref().map(|t| (g, t)))
    {
        textures += &format!(
            "<figure><img src=\"{}\" alt=\"texture of {}\"><figcaption>{}: {}×{} texels of {:.4} (scene units), {} of {} seen in the photo ({:.0}%; the rest filled from their neighbours{}), smoothing {} (cross-validated), lobe on top: {}; linear reflectance in <a href=\"{}\">{}</a></figcaption></figure>\n",
            embedded(dir, &t.preview),
            esc(&g.name),
            esc(&g.name),
            t.width,
            t.height,
            t.texel_size,
            t.texels_seen,
            t.texels,
            100.0 * t.texels_seen as f64 / t.texels.max(1) as f64,
            if t.texels_repeated > 0 {
                format!(
                    ", {} of them from the print's repeat",
                    t.texels_repeated
                )
            } else {
                String::new()
            },
            t.smoothing,
            t.lobe,
            esc(&t.file),
            esc(&t.file)
        );
    }
    if !textures.is_empty() {
        textures = format!(
            "<h2>Recovered textures (level 7)</h2>\n<p>Reflectance, the light that fell on them divided out (§5.2 of the notes); sRGB previews.</p>\n{textures}"
        );
    }
    let mut views = String::new();
    let photos = res
        .inputs
        .as_ref()
        .map(|i| i.photos.as_slice())
        .unwrap_or(&[]);
    for (k, v) in res.views.iter().enumerate() {
        views += &format!(
            "<tr><td>{}</td><td>{}</td><td>{:.4}</td><td>{:.2}%</td><td>{}</td></tr>\n",
            esc(&v.name),
            esc(photos.get(k).map_or("", |p| p.as_str())),
            v.exposure,
            100.0 * v.residual,
            v.pixels
        );
    }
    if !views.is_empty() {
        views = format!(
            "<h2>Photos fitted together</h2>\n<p>One set of materials for every photo, each through its own view (camera and lights). k: the photo's fitted exposure factor (photo = k × the recovered scene's radiance; the factors' geometric mean is 1, so the materials' scale is the photos' consensus). Residual: Σ|photo/k − model| / Σ photo/k over the photo's cached pixels of the uniform groups, last iteration. The images above are the first photo's.</p>\n<table id=\"views\"><tr><th>view</th><th>photo</th><th>k</th><th>residual</th><th>pixels</th></tr>\n{views}</table>\n"
        );
    }
    if let Some(s) = &res.stray_light {
        let c = |v: [f32; 3]| format!("{:.4}, {:.4}, {:.4}", v[0], v[1], v[2]);
        let sigma = match s.sigma {
            [Some(r), Some(g), Some(b)] => c([r, g, b]),
            _ => "not determined in some channel (kept as given)".into(),
        };
        views += &format!(
            "<h2>Stray light</h2>\n<p id=\"stray-light\">A constant environment of radiance ({}) W/(m² sr), 1σ ({sigma}), fitted with the materials: {:.1}% of the seen light. It lights what every ray leaving the scene would see; <code>recovered.toml</code> keeps it as <code>[stray_light]</code>.</p>\n",
            c(s.radiance),
            100.0 * s.share
        );
    }
    let mut convergence = String::new();
    for (g, svg) in plots {
        convergence += &format!(
            "<figure class=\"plot\" data-group=\"{}\">{svg}</figure>\n",
            esc(g)
        );
    }
    if !convergence.is_empty() {
        convergence = format!(
            "<h2>Convergence</h2>\n<p>Per group, ε of each global iteration's fit on its cache (black) and the noise floor below which it cannot go (grey), log scale; red: the level it moved to, green: where it was confirmed (log.jsonl has every decision).</p>\n{convergence}"
        );
    }
    let (photo, synthetic, error) = (
        embedded(dir, "photo.png"),
        embedded(dir, "synthetic.png"),
        embedded(dir, "error.png"),
    );
    let bar = colour_bar(scale);
    let (spp, tile) = (res.timing.final_spp, res.timing.error_tile_px);
    let inputs = match &res.inputs {
        Some(i) => {
            let reg = i.registration.as_ref().map_or("off".to_string(), |r| {
                format!(
                    "{}{}{}",
                    r.found(),
                    if r.applied {
                        String::new()
                    } else {
                        format!(" ({})", r.not_applied_because())
                    },
                    match r.shading {
                        crate::prepare::pose::Shading::SceneFile => "",
                        crate::prepare::pose::Shading::QuickFit =>
                            " (refined against a quick fit's materials)",
                    }
                )
            });
            let options = serde_json::to_string_pretty(&i.options).unwrap_or_default();
            format!(
                "<h2>Inputs</h2>\n<table id=\"inputs\"><tr><td>matfit</td><td>{}</td></tr><tr><td>scene</td><td>{}</td></tr><tr><td>photo</td><td>{}</td></tr><tr><td>exposure k</td><td>{} ({})</td></tr><tr><td>registration</td><td>{}</td></tr>{}</table>\n<details><summary>options</summary><pre>{}</pre></details>\n",
                esc(&i.matfit),
                esc(&i.scene),
                esc(&i.photo),
                i.exposure,
                esc(&i.exposure_rule),
                esc(&reg),
                i.ignore_mask.as_ref().map_or(String::new(), |m| format!(
                    "<tr><td>ignore mask</td><td>{}</td></tr>",
                    esc(m)
                )),
                esc(&options)
            )
        }
        None => String::new(),
    };
    let verdict = match &res.verdict {
        Some(v) => format!(
            "<p id=\"verdict\" style=\"{}\">{}</p>",
            if v.explained {
                ""
            } else {
                "background:#fdd;padding:0.5em;border:1px solid #c00"
            },
            esc(&v.text())
        ),
        None => String::new(),
    };
    format!(
        r#"<!doctype html>
<html><head><meta charset="utf-8"><title>matfit recovery</title>
<style>body{{font-family:sans-serif;margin:2em}} img{{max-width:32%;margin-right:1%;image-rendering:pixelated}} figure img{{min-width:256px;max-width:60%}} figure.plot{{display:inline-block;margin:0.3em}}
#compare{{position:relative;display:inline-block;max-width:66%}} #compare img{{max-width:100%;width:100%;margin:0;display:block}} #over{{position:absolute;top:0;left:0;height:100%;width:50%;overflow:hidden}} #over img{{width:auto;max-width:none;height:100%}} #slider{{display:block;width:40%}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:4px 8px;font-size:90%}}</style></head>
<body><h1>matfit recovery</h1>
{verdict}
<p>photo | synthetic | model error: per 8×8-pixel tile of each group, |Σ (synthetic − photo)| beyond three times what the pixels' scatter explains (the noise of both images), over the tile's radiance, so noise shows black (dark grey: pixels not used; error.exr has |synthetic − photo| per pixel)</p>
<p><img src="{photo}" alt="photo"><img src="{synthetic}" alt="synthetic"><img src="{error}" alt="error"></p>
{bar}
<h2>Before / after</h2>
<p>The synthetic image over the photo: left of the edge the synthetic image, right of it the photo; drag the slider.</p>
<div id="compare"><img class="under" src="{photo}" alt="photo"><div id="over"><img src="{synthetic}" alt="synthetic"></div></div>
<input id="slider" type="range" min="0" max="100" value="50" aria-label="photo / synthetic">
<table><tr><th>group</th><th>level</th><th>status</th><th>ε</th><th>noise floor</th><th>usable px</th><th>parameters</th><th>albedo</th><th>note</th></tr>
{rows}</table>
{views}
{convergence}
{textures}
<p>{} global iterations, {} cache builds, {} objective evaluations; total {:.1} s: fitting {:.1} s, final render {:.1} s ({spp} spp); Ward variant {}.</p>
{inputs}
<p>ε: Σ|synthetic − photo| / Σ photo over the group's usable pixels and channels of the final render, each image first summed over {tile}×{tile}-pixel squares (at least 1,024 samples each, so that noise averages out and a model's systematic error stays); noise floor: the same between two independent halves of its samples. A note's <i>fit ε</i> (a fraction) is the same metric on the fitter's cache at its last fit, what the hierarchy decided on (results.json <code>fit_error</code>).</p>
<p>The log of every decision is <a href="log.jsonl">log.jsonl</a>; the recovered scene is <a href="recovered.toml">recovered.toml</a>.</p>
<script>
// The slider uncovers the synthetic image over the photo.
const over = document.getElementById('over'), slider = document.getElementById('slider');
const under = document.querySelector('#compare img.under');
function place() {{ over.style.width = slider.value + '%'; over.firstElementChild.style.width = under.clientWidth + 'px'; }}
slider.addEventListener('input', place); window.addEventListener('resize', place);
// How many pictures decoded (read by the browser test).
window.addEventListener('load', () => {{
  place();
  const imgs = [...document.images];
  document.body.dataset.imagesLoaded = imgs.filter(i => i.complete && i.naturalWidth > 0).length + '/' + imgs.length;
}});
</script>
</body></html>
"#,
        res.iterations,
        res.cache_builds,
        res.objective_evals,
        res.timing.total_s,
        res.timing.fit_s,
        res.timing.final_render_s,
        res.ward_variant
    )
}

/// `page` with a section of preformatted `text` under `title` inserted after the parameter
/// table (before the convergence plots, else at the end of the body).
pub fn with_section(page: &str, title: &str, text: &str) -> String {
    let section = format!("<h2>{}</h2>\n<pre>{}</pre>\n", esc(title), esc(text));
    let at = page
        .find("<h2>Convergence</h2>")
        .or_else(|| page.rfind("</body>"))
        .unwrap_or(page.len());
    format!("{}{section}{}", &page[..at], &page[at..])
}
