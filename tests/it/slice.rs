//! `dmdsl slice` as a user runs it.

use crate::common::*;

#[test]
fn slices_box_fixture_into_bundle() {
    let dir = tempdir("box");
    let o = run_in(
        &dir,
        &[
            "slice",
            root().join("../shared/models/box.stl").to_str().unwrap(),
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("box.dmdjob");
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap();
    assert_eq!(job["format"], "dmdsl-job");
    assert_eq!(job["layers"].as_array().unwrap().len(), 500);
    let (w, h, px) = read_gray(&b.join("masks/00000.png"));
    assert_eq!((w, h), (1024, 768));
    assert!(px.iter().any(|&v| v == 255));
}
