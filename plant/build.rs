//! `chaosd-plant-mujoco` finds the MuJoCo library where it was linked from: the build records
//! `MUJOCO_DYNAMIC_LINK_DIR` as the binary's run path, so no `LD_LIBRARY_PATH` is needed.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_none() {
        return;
    }
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg-bin=chaosd-plant-mujoco=-Wl,-rpath,{dir}");
    }
}
