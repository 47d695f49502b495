//! The dashboard: a page, a style sheet and one script embedded in the binary, polling the
//! JSON API. The script is written as several files, one per view (`common.js`: the API call,
//! builders, formatting and the time axis; `charts.js`: the machine page's charts;
//! `planner.js`: the fleet by urgency and the open alerts; `projection.js`: the wear trend
//! with its projected crossings; `evidence.js`: a record's spectra with the lines its findings
//! rest on; `diagnosis.js`: one record's diagnosis; `app.js`: routes and
//! polling), served as one `/app.js` in that order. The page itself holds no data; its API calls need a read key (asked for on a 401, kept in the
//! browser's sessionStorage for the tab's life, sent as `Authorization: Bearer`) unless the
//! operator started the service with `--dashboard-without-key`.

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

const INDEX: &str = include_str!("dashboard/index.html");
const APP_JS: &str = concat!(
    include_str!("dashboard/common.js"),
    "\n",
    include_str!("dashboard/charts.js"),
    "\n",
    include_str!("dashboard/planner.js"),
    "\n",
    include_str!("dashboard/projection.js"),
    "\n",
    include_str!("dashboard/evidence.js"),
    "\n",
    include_str!("dashboard/diagnosis.js"),
    "\n",
    include_str!("dashboard/app.js"),
);
const STYLE: &str = include_str!("dashboard/style.css");

fn asset(body: &'static str, ct: &'static str) -> Response {
    let mut r = body.into_response();
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(ct));
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r
}

pub async fn index() -> Response {
    asset(INDEX, "text/html; charset=utf-8")
}

pub async fn app_js() -> Response {
    asset(APP_JS, "text/javascript; charset=utf-8")
}

pub async fn style() -> Response {
    asset(STYLE, "text/css; charset=utf-8")
}
