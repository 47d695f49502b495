//! The service's one list of routes: each route's method, path template, the access it needs
//! and its handler. The router is built from it ([`super::router`]); the tests check it against
//! `openapi.yaml` (the same routes, public exactly where the spec says `security: []`) and send
//! every route a request without a key, with each scope's key and with bad keys, expecting what
//! [`Route::access`] says.

use axum::handler::Handler;
use axum::http::Method;
use axum::routing::{MethodFilter, MethodRouter, on};

use super::{
    AppState, alerts, calibration, dashboard, gearboxes, health, lifecycle, machines, read,
    records, trend, webhooks,
};
use crate::keys::Scope;

/// What a route needs of its caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// No key (health, metrics, the dashboard's static files).
    Public,
    /// A key granting this scope (`admin` grants every scope).
    Key(Scope),
}

/// One route.
pub struct Route {
    pub method: Method,
    /// The path template (`/v1/machines/{machine_id}`), as in `openapi.yaml`.
    pub path: &'static str,
    pub access: Access,
    pub handler: MethodRouter<AppState>,
}

fn route<H, T>(method: Method, path: &'static str, access: Access, handler: H) -> Route
where
    H: Handler<T, AppState>,
    T: 'static,
{
    let filter = MethodFilter::try_from(method.clone()).expect("a method axum routes");
    Route {
        method,
        path,
        access,
        handler: on(filter, handler),
    }
}

/// Every route of the service.
pub fn routes() -> Vec<Route> {
    use Access::{Key, Public};
    use Scope::{Acknowledge, Admin, Ingest, Read};
    const GET: Method = Method::GET;
    const PUT: Method = Method::PUT;
    const POST: Method = Method::POST;
    const DELETE: Method = Method::DELETE;
    const MACHINE: &str = "/v1/machines/{machine_id}";
    const BASELINE: &str = "/v1/machines/{machine_id}/baseline";
    const CALIBRATION: &str = "/v1/machines/{machine_id}/calibration";
    const GEARBOX: &str = "/v1/gearboxes/{gearbox_id}";
    const WEBHOOKS: &str = "/v1/webhooks";
    vec![
        route(GET, "/v1/machines", Key(Read), read::list_machines),
        route(GET, MACHINE, Key(Read), read::get_machine),
        route(PUT, MACHINE, Key(Admin), machines::put),
        route(DELETE, MACHINE, Key(Admin), lifecycle::delete),
        route(GET, BASELINE, Key(Read), machines::get_baseline),
        route(POST, BASELINE, Key(Admin), machines::post_baseline),
        route(DELETE, BASELINE, Key(Admin), machines::delete_baseline),
        route(
            DELETE,
            "/v1/machines/{machine_id}/baseline/{record_id}",
            Key(Admin),
            machines::delete_baseline_record,
        ),
        route(GET, "/v1/gearboxes", Key(Read), gearboxes::list),
        route(GET, GEARBOX, Key(Read), gearboxes::get),
        route(PUT, GEARBOX, Key(Admin), gearboxes::put),
        route(
            POST,
            "/v1/machines/{machine_id}/records",
            Key(Ingest),
            records::post_record,
        ),
        route(
            GET,
            "/v1/machines/{machine_id}/diagnoses",
            Key(Read),
            read::list_diagnoses,
        ),
        route(
            GET,
            "/v1/machines/{machine_id}/trend",
            Key(Read),
            trend::get_trend,
        ),
        route(POST, CALIBRATION, Key(Admin), calibration::post),
        route(GET, CALIBRATION, Key(Read), calibration::get),
        route(DELETE, CALIBRATION, Key(Admin), calibration::delete),
        route(
            GET,
            "/v1/diagnoses/{diagnosis_id}",
            Key(Read),
            read::get_diagnosis,
        ),
        route(GET, "/v1/alerts", Key(Read), alerts::list),
        route(GET, "/v1/alerts/{alert_id}", Key(Read), alerts::get),
        route(
            POST,
            "/v1/alerts/{alert_id}/acknowledge",
            Key(Acknowledge),
            alerts::acknowledge,
        ),
        route(POST, WEBHOOKS, Key(Admin), webhooks::create),
        route(GET, WEBHOOKS, Key(Admin), webhooks::list),
        route(
            DELETE,
            "/v1/webhooks/{webhook_id}",
            Key(Admin),
            webhooks::delete,
        ),
        route(
            GET,
            "/v1/webhooks/{webhook_id}/deliveries",
            Key(Admin),
            webhooks::deliveries,
        ),
        route(GET, "/v1/records/{record_id}", Key(Read), read::get_record),
        route(GET, "/healthz", Public, health::healthz),
        route(GET, "/readyz", Public, health::readyz),
        route(GET, "/metrics", Public, health::metrics),
        route(GET, "/", Public, dashboard::index),
        route(GET, "/app.js", Public, dashboard::app_js),
        route(GET, "/style.css", Public, dashboard::style),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_method_and_path_is_listed_once() {
        let rs = routes();
        let mut seen = std::collections::BTreeSet::new();
        for r in &rs {
            assert!(
                seen.insert((r.method.to_string(), r.path)),
                "{} {} is listed twice",
                r.method,
                r.path
            );
        }
        assert!(rs.iter().any(|r| r.access == Access::Public));
    }
}
