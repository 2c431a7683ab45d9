//! Embeds every file of the workspace's `config/` directory into the binary, so that `sextant
//! run` works from any directory (`sextant::config::embedded_config_files`).

use std::path::{Path, PathBuf};

fn walk(dir: &Path, base: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, base, out);
        } else if p.extension().is_some_and(|e| e == "toml")
            && let Ok(rel) = p.strip_prefix(base)
        {
            out.push((rel.to_string_lossy().into_owned(), p.clone()));
        }
    }
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let config = manifest.join("..").join("config");
    println!("cargo:rerun-if-changed={}", config.display());
    let mut files = Vec::new();
    walk(&config, &config, &mut files);
    for (_, p) in &files {
        println!("cargo:rerun-if-changed={}", p.display());
    }
    let mut src = String::from("&[\n");
    for (rel, p) in &files {
        src.push_str(&format!(
            "    ({rel:?}, include_str!({:?})),\n",
            p.display().to_string()
        ));
    }
    src.push_str("]\n");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it"));
    std::fs::write(out.join("embedded_config.rs"), src).expect("write embedded_config.rs");
}
