//! Links the system Embree 3 library, or stops the build with a message saying how to install it.

use std::path::Path;

fn main() {
    println!("cargo:rerun-if-env-changed=EMBREE_LIB_DIR");
    let mut dirs: Vec<String> = vec![
        "/usr/lib/x86_64-linux-gnu".into(),
        "/usr/lib/aarch64-linux-gnu".into(),
        "/usr/lib".into(),
        "/usr/local/lib".into(),
        "/usr/lib64".into(),
    ];
    if let Ok(d) = std::env::var("EMBREE_LIB_DIR") {
        dirs.insert(0, d);
    }
    let found = dirs
        .iter()
        .find(|d| Path::new(d).join("libembree3.so").exists() || Path::new(d).join("libembree3.so.3").exists());
    match found {
        Some(d) => {
            println!("cargo:rustc-link-search=native={d}");
            if Path::new(d).join("libembree3.so").exists() {
                println!("cargo:rustc-link-lib=dylib=embree3");
            } else {
                println!("cargo:rustc-link-arg=-l:libembree3.so.3");
            }
        }
        None => panic!(
            "\n\nEmbree 3 (libembree3) was not found.\n\
             The comparison harness links the system Embree 3.13.5 library. Install it with\n\
             \n    sudo apt-get update && sudo apt-get install -y libembree-dev\n\n\
             or point EMBREE_LIB_DIR at the folder holding libembree3.so.\n"
        ),
    }
}
