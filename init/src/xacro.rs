//! A `.xacro` description expanded by the `xacro` tool (PyPI's `xacro`, or
//! ROS's), as `ros2 launch` would; any other file is read as URDF.
use crate::error::InitError;
use std::path::Path;
use std::process::Command;

const HOW: &str = "install it (`pip install xacro`) or expand the file yourself: `xacro ROBOT.urdf.xacro > ROBOT.urdf`";

pub fn read(path: &Path) -> Result<String, InitError> {
    let is_xacro = path.extension().is_some_and(|e| e == "xacro");
    if !is_xacro {
        // bounded, and a byte that is not UTF-8 named at its line
        return kinegen_model::files::read_text(path).map_err(|(at, e)| {
            InitError::at(
                path,
                at.map(|(line, _)| line),
                format!("cannot read the URDF: {e}"),
            )
        });
    }
    if !path.is_file() {
        return Err(InitError::at(
            path,
            None,
            "cannot read the description: no such file",
        ));
    }
    let out = Command::new("xacro").arg(path).output().map_err(|e| {
        InitError::at(
            path,
            None,
            format!("a .xacro file needs the `xacro` tool, which cannot be run here ({e}): {HOW}"),
        )
    })?;
    if !out.status.success() {
        let why = String::from_utf8_lossy(&out.stderr);
        return Err(InitError::at(
            path,
            None,
            format!("xacro could not expand it: {}", why.trim()),
        ));
    }
    String::from_utf8(out.stdout)
        .map_err(|_| InitError::at(path, None, "xacro's output is not UTF-8 text"))
}
