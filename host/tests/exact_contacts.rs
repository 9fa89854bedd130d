//! The shipped bank, the tool's pairs (host/scenes/liver.toml, `bank.couplings = "tool"`), fits
//! the demo's 128 KiB and is exact
//! on every contact the tool can make: at 1,200 contact sites spread over the reachable surface (area-uniform,
//! anchors off the lattice the bank's pairs were sampled on), the firmware's force (f32, its own
//! patch and solve on the bank's bytes) is within 1e-4 relative of the f64 solve on untruncated
//! compliance, for a point contact (barycentric weights) and for the scene's 3 mm tool patch.
//! The reference weights are the firmware's patch rule on a probe bank that couples every pair
//! a patch can load (see `host::bank::sweep`); the reference forces come from the compliance's
//! direct solves, not from the bank.

use bank_format::{AlignedBytes, Bank};
use host::bank::Prepared;
use host::bank::sweep;
use std::path::Path;

#[test]
fn the_tool_bank_is_exact_on_every_contact_the_tool_can_make() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver.toml");
    let prep = Prepared::load(&scene).unwrap();
    assert_eq!(prep.scene.bank.couplings, host::scene::Couplings::Tool);
    let built = prep.build_bank(None).unwrap();
    assert!(
        built.bytes.len() <= 128 * 1024,
        "the tool bank is {} bytes, over the demo's 128 KiB",
        built.bytes.len()
    );
    let aligned = AlignedBytes::new(&built.bytes);
    let bank = Bank::parse(&aligned).unwrap();

    let rows = prep.blocks(prep.probe_radius(), None).unwrap();
    let probe_bytes = sweep::probe_bytes(&prep, &rows).unwrap();
    let probe = Bank::parse(&probe_bytes).unwrap();
    let sites = sweep::sites(&probe, 1200, 0.005, 7);
    assert_eq!(sites.len(), 1200);
    let refs = sweep::references(&prep, &probe, &sites).unwrap();

    // The patch on the demo bank is the patch on the probe bank, bit for bit: no node is
    // dropped for want of a coupling, and the nodal pressures see the same nodes.
    let radius = prep.scene.tip_radius_m as f32;
    for s in &sites {
        let tri = bank.triangles()[s.triangle];
        let on_bank =
            firmware::patch::tool_patch(&bank, s.triangle as u32, tri, s.bary, s.anchor, radius);
        let on_probe =
            firmware::patch::tool_patch(&probe, s.triangle as u32, tri, s.bary, s.anchor, radius);
        assert_eq!(on_bank, on_probe, "site {s:?}");
    }

    let e = sweep::errors(&prep, &bank, &refs);
    eprintln!(
        "tool bank {} bytes, {} pairs; {} sites: point contact max {:.2e} mean {:.2e}, tool \
         patch max {:.2e} mean {:.2e}, load dropped max {:.2e}",
        built.bytes.len(),
        built.pairs,
        refs.len(),
        e.point_max,
        e.point_mean,
        e.patch_max,
        e.patch_mean,
        e.dropped_max
    );
    assert_eq!(e.failed, 0, "{e:?}");
    assert!(e.point_max <= 1e-4, "{e:?}");
    assert!(e.patch_max <= 1e-4, "{e:?}");
}
