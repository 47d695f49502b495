//! `openapi.yaml` and the router agree: the same (method, path) pairs, every operation
//! documents its responses. (Response bodies are validated against the spec's schemas in
//! every API test through `helpers::checked`.)

use std::collections::BTreeSet;

use crate::helpers::spec;

#[test]
fn routes_and_spec_paths_are_the_same_set() {
    let mut in_spec = BTreeSet::new();
    for (path, item) in spec()["paths"].as_object().unwrap() {
        for (method, _) in item.as_object().unwrap() {
            if ["get", "post", "put", "patch", "delete"].contains(&method.as_str()) {
                in_spec.insert((method.to_ascii_uppercase(), path.clone()));
            }
        }
    }
    let in_router: BTreeSet<(String, String)> = gearwear::service::routes::routes()
        .iter()
        .map(|r| (r.method.to_string(), r.path.to_string()))
        .collect();
    let missing: Vec<_> = in_router.difference(&in_spec).collect();
    let extra: Vec<_> = in_spec.difference(&in_router).collect();
    assert!(
        missing.is_empty(),
        "routes missing from openapi.yaml: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "openapi.yaml documents routes the router lacks: {extra:?}"
    );
    assert_eq!(spec()["openapi"].as_str().unwrap(), "3.1.0");
}

/// Every route of the route list is really served (not the 404 fallback), and nothing else is.
#[tokio::test]
async fn router_serves_exactly_the_listed_routes() {
    use axum::body::Body;
    use axum::http::Request;
    use tower::ServiceExt;
    let Some(app) = crate::helpers::spawn_app(crate::helpers::Backend::Sqlite, |_| {}).await else {
        return;
    };
    let state = gearwear::service::AppState::new(
        app.settings.clone(),
        app.store.clone(),
        crate::helpers::diagnoser(),
    );
    for r in gearwear::service::routes::routes() {
        let (m, p) = (r.method, r.path);
        let uri = p.replace('{', "x").replace('}', "");
        let req = Request::builder()
            .method(m.clone())
            .uri(&uri)
            .body(Body::empty())
            .unwrap();
        let r = gearwear::service::router(state.clone())
            .oneshot(req)
            .await
            .unwrap();
        let body = axum::body::to_bytes(r.into_body(), 1 << 20).await.unwrap();
        assert!(
            !String::from_utf8_lossy(&body).contains("problem:not-found\""),
            "{m} {p} is in the route list but the router answers with its fallback"
        );
    }
}

#[test]
fn every_schema_reference_resolves_and_compiles() {
    let text = serde_json::to_string(spec()).unwrap();
    for r in text.split("\"$ref\":\"").skip(1) {
        let r = &r[..r.find('"').unwrap()];
        assert!(
            spec().pointer(r.trim_start_matches('#')).is_some(),
            "dangling {r}"
        );
    }
    for (name, s) in spec()["components"]["schemas"].as_object().unwrap() {
        let mut s = s.clone();
        s["components"] = spec()["components"].clone();
        assert!(
            jsonschema::draft202012::new(&s).is_ok(),
            "schema {name} does not compile"
        );
    }
}
