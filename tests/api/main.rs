//! Integration tests of the HTTP service: one binary, one `spawn_app()` (random port, fresh
//! SQLite file or fresh PostgreSQL database), the same API tests on both stores.

mod helpers;

mod alerts;
mod api;
mod assessment;
mod bad_records;
mod browser;
mod calibration;
mod cli;
mod doors;
mod evidence;
mod faults;
mod gearboxes;
mod lifecycle;
mod machine_page;
mod mqtt;
mod openapi;
mod operating_state;
mod own_model;
mod planner;
mod quality_battery;
mod record_page;
mod security;
mod store;
mod tables;
mod trend;
mod units;
mod webhooks;
