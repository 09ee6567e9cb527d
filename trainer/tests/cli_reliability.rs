//! Issue 27 ("no input crashes `cbd`, no output destroys a file, no damaged model is used"): one
//! test per item, through the real binary.

mod cli_support;

use cli_support::*;

/// Item 1: a DH or planar fit on fewer measured coordinates than parameters indexed past the thin
/// SVD (`index out of bounds: the len is 30 but the index is 30`). Now fitted (rank-deficient DH,
/// minimum norm); two rows are refused as too few.
#[test]
fn few_rows_in_dh_and_planar_fits() {
    let dir = scratch("few-rows");
    let ur10 = ur5_head(&dir, "ur10.csv", 10);
    let model = ur5_model();
    let err = succeeds(&cbd(&dir, &["fit", "--dh-first", "--model", &model, "--data", &ur10, "--out", "x.blob", "--quiet"]));
    assert!(err.contains("DH calibration") && err.contains("rank"), "{err}");
    succeeds(&cbd(&dir, &["compare", "--model", &model, "--train", &ur10, "--test", &ur10]));
    let planar = write(&dir, "rr.toml", PLANAR_RR_MODEL);
    let grid = rr_grid(&dir, "g4.csv", 4);
    for rows in [8, 3] {
        let few = head(&dir, &grid, &format!("p{rows}.csv"), rows);
        succeeds(&cbd(&dir, &["compare", "--model", &planar, "--train", &few, "--test", &few]));
    }
    let two = head(&dir, &grid, "p2.csv", 2);
    fails_with(&cbd(&dir, &["fit", "--data", &two, "--out", "x.blob"]), &["p2.csv", "2", "at least 3"]);
}

/// Item 4: a URDF of 30 000 nested elements (210 KB) overflowed the stack (abort). Now refused
/// with the URDF's name, line and column.
#[test]
fn deeply_nested_urdf_is_refused() {
    let dir = scratch("deep-urdf");
    let n = 30_000;
    write(&dir, "deep.urdf", format!("<robot name=\"r\">{}{}</robot>", "<a>".repeat(n), "</a>".repeat(n)));
    let model = write(
        &dir,
        "deep.toml",
        "length_unit = \"m\"\nangle_unit = \"rad\"\n[urdf]\npath = \"deep.urdf\"\nbase_link = \"a\"\ntip_link = \"b\"\n",
    );
    let grid = rr_grid(&dir, "g4.csv", 4);
    fails_with(
        &cbd(&dir, &["fit", "--model", &model, "--data", &grid, "--out", "d.blob"]),
        &["deep.urdf", "line 1", "nested more than 64 deep"],
    );
}
