//! Converts an RGB-D sequence from one dataset layout into another, to run a capture through a
//! reader (or a tool) that expects that layout:
//!
//! ```sh
//! cargo run --release -p cpose-slam --example rgbd_convert -- \
//!     7scenes ../shared/data/7scenes/redkitchen_0000_0499 tum redkitchen_tum [FRAMES]
//! ```
//!
//! Sources: `7scenes`, `replica`, `scannet`, `tum`; destinations: `replica`, `scannet`, `tum`
//! (`cpose_slam::data::write_sequence`). Frames without timestamps get 30 Hz. The destination must
//! be a new or empty folder.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use cpose_slam::data::{
    Layout, read_replica, read_scannet, read_seven_scenes, read_tum_rgbd, write_sequence,
};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(4..=5).contains(&args.len()) {
        eprintln!(
            "usage: rgbd_convert FROM SRC TO DST [FRAMES]\n  \
             FROM: 7scenes, replica, scannet, tum\n  TO: replica, scannet, tum"
        );
        return ExitCode::from(2);
    }
    let (src, dst) = (PathBuf::from(&args[1]), PathBuf::from(&args[3]));
    let Some(layout) = Layout::from_name(&args[2]) else {
        eprintln!(
            "rgbd_convert: unknown layout {:?} (replica, scannet, tum)",
            args[2]
        );
        return ExitCode::from(2);
    };
    let frames = match args.get(4).map(|n| n.parse::<usize>()) {
        None => None,
        Some(Ok(n)) => Some(n),
        Some(Err(_)) => {
            eprintln!("rgbd_convert: FRAMES must be a count, got {:?}", args[4]);
            return ExitCode::from(2);
        }
    };
    let seq = match args[0].as_str() {
        "7scenes" => read_seven_scenes(&src, 1.0, 30.0),
        "replica" => read_replica(&src, None, 1.0, 30.0),
        "scannet" => read_scannet(&src, 1.0),
        "tum" => read_tum_rgbd(&src, None, 1.0),
        other => {
            eprintln!(
                "rgbd_convert: unknown source layout {other:?} (7scenes, replica, scannet, tum)"
            );
            return ExitCode::from(2);
        }
    };
    match seq.and_then(|seq| write_sequence(&seq, layout, &dst, frames)) {
        Ok(()) => {
            let _ = writeln!(std::io::stdout(), "{}", dst.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("rgbd_convert: {e}");
            ExitCode::FAILURE
        }
    }
}
