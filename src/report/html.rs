//! The HTML report: photo | synthetic | error side by side, and the parameter table.

use super::Results;
use crate::fit::params::Value;

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

pub fn report(res: &Results) -> String {
    let mut rows = String::new();
    for g in &res.groups {
        let params: Vec<String> = g
            .params
            .iter()
            .map(|(k, v)| match g.sigma.get(k) {
                Some(sd) => format!("{k} = {} ± {}", value(v), value(sd)),
                None => format!("{k} = {}", value(v)),
            })
            .collect();
        let pct = |x: Option<f32>| x.map_or("–".to_string(), |e| format!("{:.2}%", 100.0 * e));
        rows += &format!(
            "<tr><td>{}</td><td>{} ({})</td><td>{:?}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            esc(&g.name),
            g.level,
            g.level_number,
            g.status,
            pct(g.error),
            pct(g.noise_floor),
            g.usable_pixels,
            esc(&params.join(", ")),
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
            "<figure><img src=\"{}\" alt=\"texture of {}\"><figcaption>{}: {}×{} texels of {:.4} (scene units), {} of {} seen in the photo ({:.0}%; the rest filled from their neighbours), lobe on top: {}; linear reflectance in <a href=\"{}\">{}</a></figcaption></figure>\n",
            esc(&t.preview),
            esc(&g.name),
            esc(&g.name),
            t.width,
            t.height,
            t.texel_size,
            t.texels_seen,
            t.texels,
            100.0 * t.texels_seen as f64 / t.texels.max(1) as f64,
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
    format!(
        r#"<!doctype html>
<html><head><meta charset="utf-8"><title>matfit recovery</title>
<style>body{{font-family:sans-serif;margin:2em}} img{{max-width:32%;margin-right:1%;image-rendering:pixelated}} figure img{{min-width:256px;max-width:60%}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:4px 8px;font-size:90%}}</style></head>
<body><h1>matfit recovery</h1>
<p>photo | synthetic | relative error (black 0 → white ≥ 20%; grey: pixels not used)</p>
<p><img src="photo.png" alt="photo"><img src="synthetic.png" alt="synthetic"><img src="error.png" alt="error"></p>
<table><tr><th>group</th><th>level</th><th>status</th><th>ε</th><th>noise floor</th><th>usable px</th><th>parameters</th><th>note</th></tr>
{rows}</table>
{textures}
<p>{} global iterations, {} cache builds, {} objective evaluations; total {:.1} s, final render {:.1} s; Ward variant {}.</p>
<p>ε: Σ|synthetic − photo| / Σ photo over the group's usable pixels and channels, final render; noise floor: the same between two independent halves of its samples. A note's <i>fit ε</i> (a fraction) is the same metric on the fitter's cache at its last fit, what the hierarchy decided on (results.json <code>fit_error</code>).</p>
<p>The log of every decision is <a href="log.jsonl">log.jsonl</a>; the recovered scene is <a href="recovered.toml">recovered.toml</a>.</p>
</body></html>
"#,
        res.iterations,
        res.cache_builds,
        res.objective_evals,
        res.timing.total_s,
        res.timing.final_render_s,
        res.ward_variant
    )
}
