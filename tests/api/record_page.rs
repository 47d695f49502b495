//! The record page in a real headless Chromium: a machine with the PHM 2009 helical gearbox
//! described and a tachometer, four healthy records at one state as its baseline, then a
//! record with a damaged idler shaft. Its page draws the order spectrum over the healthy
//! reference and the envelope spectrum, with the mesh harmonics, sidebands, shaft lines and
//! bearing defect orders marked and labelled (no two labels overlapping); selecting a finding
//! highlights the lines it rests on. The page's data (`GET /v1/diagnoses/{id}`) is measured
//! against the 200 kB target, and a screenshot is written for the docs
//! (`GEARWEAR_SCREENSHOT_DIR`, else `target/screenshots/`).

use std::path::PathBuf;

use base64::Engine;
use serde_json::{Value, json};

use crate::browser::{Driver, start_driver};
use crate::doors::post;
use crate::gearboxes::put_gearbox;
use crate::helpers::*;
use crate::operating_state::{HELICAL, PPR, record};

/// The record page's data budget.
const MAX_PAGE_BYTES: usize = 200_000;

/// The marked lines of one chart: `{kind, feature, label, shown}` (`shown`: the label placed).
async fn marks(d: &Driver, svg: &str) -> Vec<Value> {
    let js = format!(
        "return [...document.querySelectorAll('#{svg} g.ev-mark')].map(g => ({{kind: \
         g.dataset.kind, feature: g.dataset.feature, label: g.dataset.label, hl: \
         g.classList.contains('hl'), shown: !!g.querySelector('text.ev-label')}}));"
    );
    d.script(&js).await.as_array().cloned().unwrap_or_default()
}

/// Pairs of placed labels whose boxes overlap in `svg`.
async fn overlaps(d: &Driver, svg: &str) -> Value {
    d.script(&format!(
        "const b = [...document.querySelectorAll('#{svg} text.ev-label')].map(t => \
         [t.textContent, t.getBBox()]); const out = []; \
         for (let i = 0; i < b.length; i++) for (let j = i + 1; j < b.length; j++) {{ \
         const [p, q] = [b[i][1], b[j][1]]; \
         if (p.x < q.x + q.width && q.x < p.x + p.width && p.y < q.y + q.height && q.y < p.y + p.height) \
         out.push([b[i][0], b[j][0]]); }} return out;"
    ))
    .await
}

fn shown(ms: &[Value], kind: &str, label: impl Fn(&str) -> bool) -> bool {
    ms.iter().any(|m| {
        m["kind"] == kind && m["shown"] == true && label(m["label"].as_str().unwrap_or(""))
    })
}

/// Zoom the order spectrum with the button whose text starts with `button`: each of
/// `labels` is shown on a line of `kind`, and no two labels overlap.
async fn zoomed(d: &Driver, button: &str, kind: &str, labels: &[&str]) {
    click(
        d,
        &format!("[...$('record-zoom').children].find(b => b.textContent.startsWith('{button}'))"),
    )
    .await;
    let ms = marks(d, "record-orders").await;
    for s in labels {
        assert!(shown(&ms, kind, |l| l == *s), "{button}: {s} in {ms:?}");
    }
    assert_eq!(overlaps(d, "record-orders").await, json!([]), "{button}");
}

async fn click(d: &Driver, js_element: &str) {
    let ok = d
        .script(&format!(
            "const e = {js_element}; if (!e) return false; e.click(); return true;"
        ))
        .await;
    assert_eq!(ok, json!(true), "nothing to click: {js_element}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_record_page_shows_the_evidence() {
    let Some(app) = spawn_app(Backend::Sqlite, |s| s.open_dashboard = true).await else {
        return;
    };
    let (s, g) = put_gearbox(&app, "helical", &app.admin_key, HELICAL).await;
    assert_eq!(s, 201, "{g}");
    let config = json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": PPR});
    let (s, m) = put_machine(&app, "gb", config).await;
    assert_eq!(s, 201, "{m}");
    for seed in 1..=4 {
        post(
            &app,
            "?baseline=true",
            &record(35.0, seed, false, Some("low")),
        )
        .await;
    }
    let bad = post(&app, "", &record(35.0, 102, true, Some("low"))).await;
    let findings = bad["findings"].as_array().cloned().unwrap_or_default();
    assert!(
        !findings.is_empty(),
        "the damaged record has findings: {bad}"
    );
    let id = bad["id"].as_str().unwrap();

    // The page's data, as the page fetches it (checked against openapi.yaml).
    let (s, _, bytes) = checked(
        app.client
            .get(app.url(&format!("/v1/diagnoses/{id}")))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/diagnoses/{diagnosis_id}",
    )
    .await;
    assert_eq!(s, 200);
    let text = String::from_utf8(bytes.to_vec()).unwrap();
    let page: Value = serde_json::from_str(&text).unwrap();
    let ev = &page["evidence"];
    eprintln!(
        "record page data: {} bytes (evidence {} bytes, of it the reference {} bytes)",
        text.len(),
        ev.to_string().len(),
        ev["reference"].to_string().len()
    );
    assert!(text.len() <= MAX_PAGE_BYTES, "{} bytes", text.len());
    assert_eq!(ev["channel"], bad["channel"], "{ev}");
    assert!(
        ev["reference"].is_object(),
        "a healthy reference: {}",
        ev["reference"]
    );
    assert_eq!(ev["reference"]["same_load"], true);

    let Some((d, _profile)) = start_driver().await else {
        return;
    };
    d.open(&app.url(&format!("/#/diagnoses/{id}"))).await;
    d.wait_for(
        "the order spectrum's lines",
        "return document.querySelectorAll('#record-orders g.ev-mark').length > 0",
    )
    .await;
    let facts = d.script("return $('record-facts').textContent").await;
    let facts = facts.as_str().unwrap();
    for want in [
        "counted from the tachometer",
        "Load",
        "low",
        "Deciding channel",
        "Compared with",
    ] {
        assert!(facts.contains(want), "`{want}` in the facts: {facts}");
    }
    let refs = d
        .script("return document.querySelectorAll('#record-orders polyline.ev-reference').length")
        .await;
    assert_eq!(refs, json!(1), "the healthy reference is drawn beneath");

    // Which gears make each mesh, in words.
    let key = d.script("return $('record-meshes').textContent").await;
    assert_eq!(
        key,
        json!("GM1: in 16T / idler 48T; GM2: idler 24T / out 40T"),
        "the meshes' key"
    );
    // Every order: the mesh harmonics are labelled, by stage.
    let all = marks(&d, "record-orders").await;
    assert!(shown(&all, "mesh", |l| l.contains("GM1 ×1")), "{all:?}");
    assert_eq!(overlaps(&d, "record-orders").await, json!([]));
    // The shafts' range: each shaft's 1× and 2×; around mesh 1: its sidebands at each
    // shaft's rate.
    zoomed(
        &d,
        "shafts",
        "shaft",
        &["1× in", "1× idler", "1× out", "2× idler"],
    )
    .await;
    zoomed(
        &d,
        "GM1 ×1",
        "sideband",
        &["+1 idler", "-1 idler", "+1 out", "+1 in"],
    )
    .await;
    // The envelope: bearing defect orders and the shafts' rates.
    let env = marks(&d, "record-envelope").await;
    assert!(
        shown(&env, "bearing", |l| l.starts_with("BPFI in")),
        "{env:?}"
    );
    assert!(shown(&env, "bearing", |l| l.starts_with("BPFO")), "{env:?}");
    assert!(shown(&env, "shaft-rate", |l| l == "1× idler"), "{env:?}");
    assert_eq!(overlaps(&d, "record-envelope").await, json!([]));

    // Selecting a finding highlights its lines (or the band of a whole line class), and
    // nothing else.
    let lined = findings
        .iter()
        .position(|f| {
            f["evidence"].as_array().unwrap().iter().any(|e| {
                let f = e["feature"].as_str().unwrap();
                f.starts_with("lines.") || f.starts_with("shaft.") || f.starts_with("bearing.")
            })
        })
        .expect("a finding resting on lines");
    let features: Vec<String> = findings[lined]["evidence"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["feature"].as_str().unwrap().to_string())
        .collect();
    click(
        &d,
        &format!("$('record-findings').querySelectorAll('li.finding')[{lined}]"),
    )
    .await;
    let hl = d
        .script(
            "return [...document.querySelectorAll('#record-evidence g.ev-mark.hl, \
             #record-evidence rect.ev-region.hl')].map(e => \
             e.dataset.feature || 'region:' + e.dataset.region)",
        )
        .await;
    let hl: Vec<String> = serde_json::from_value(hl).unwrap();
    assert!(
        !hl.is_empty(),
        "the finding {} highlights nothing",
        findings[lined]
    );
    for f in &hl {
        let region = f.strip_prefix("region:");
        assert!(
            features.contains(f)
                || region.is_some_and(|r| features.iter().any(|x| x.ends_with(&format!(".{r}")))),
            "{f} highlighted, the finding rests on {features:?}"
        );
    }
    let selected = d
        .script("return $('record-findings').querySelectorAll('li.finding.selected').length")
        .await;
    assert_eq!(selected, json!(1));
    assert_eq!(overlaps(&d, "record-orders").await, json!([]));
    screenshot(&d, "record-page.png").await;
    d.script("$('record-evidence').scrollIntoView(); return true;")
        .await;
    screenshot(&d, "record-evidence.png").await;
    d.cmd(reqwest::Method::DELETE, "", None).await;
}

/// The page as PNG (WebDriver `GET /screenshot`) under `GEARWEAR_SCREENSHOT_DIR`, else
/// `target/screenshots/`.
async fn screenshot(d: &Driver, name: &str) {
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(png.as_str().expect("a base64 screenshot"))
        .unwrap();
    let dir = std::env::var_os("GEARWEAR_SCREENSHOT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/screenshots"));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    eprintln!("screenshot: {}", path.display());
}
