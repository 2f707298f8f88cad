//! The integration tests, one binary with a module per area (codecs and clients against
//! byte streams and pseudo-terminals, the real `surfscan` binary against the simulator, the
//! independent Python reference checks). Tests that change process-wide state (environment
//! variables, resident memory) live in `tests/process_wide/` instead.

mod cli_conventions;
mod common;
mod config_ranges;
mod control_cli;
mod control_server;
mod daemon_e2e;
mod demo_cli;
mod fault_policy;
mod fit_geomdl;
mod fit_scipy;
mod fuzz_parsers;
mod iges_fit_cli;
mod iges_occt;
mod iges_roundtrip;
mod iges_split;
mod input_policy;
mod jobs_cli;
mod metrology_areal;
mod metrology_areal_reference;
mod metrology_cli;
mod metrology_model;
mod metrology_plots;
mod metrology_profile;
mod metrology_reference;
mod metrology_x3p;
mod model_honesty;
mod model_report;
mod mqtt_broker;
mod night_faults;
mod older_scans;
mod prometheus_scrape;
mod report_print;
mod results_unchanged;
mod scan_dir_analysis;
mod scan_e2e;
mod scan_reads_during_return;
mod scan_runner;
mod scan_storage;
mod sim_station_config;
mod sj210_client;
mod sj210_drive_timeline;
mod sj210_link_rate;
mod sj210_probe_cli;
mod sj210_readout_probe;
mod sj210_sim;
mod sj_material_ratio;
mod sj_parameters;
mod stage_grbl;
mod stage_pty;
mod stage_scan;
mod stage_zaber;
mod stage_zaber_scan;
mod station_lock;
