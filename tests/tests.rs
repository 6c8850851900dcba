//! End-to-end tests, in one binary (quicker to build on two cores than one binary per file).

mod bad_input;
mod capture;
mod cli;
mod common;
mod edit;
mod export;
mod export_gltf;
mod fuzz_replay;
mod geometry;
mod import;
mod low_resolution;
mod microfacet;
mod mirrors;
mod orthographic;
mod photo;
mod photo_inputs;
mod pose;
mod punctual;
mod recover;
mod render_physics;
mod resume;
mod scene_errors;
mod texture;
mod uncertainty;
mod unseen;
mod views;
