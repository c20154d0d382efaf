//! A short campaign on every reader (a few seconds; the full one is in `docs/input-checks.md`): no
//! panic, no error without the file's name, no allocation over the cap (the process would
//! abort), and the mutations reach both accepted and refused inputs.

use parser_fuzz::{Campaign, Parser};

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

#[test]
fn every_reader_survives_a_short_campaign() {
    let dir = std::env::temp_dir().join(format!("parser-fuzz-test-{}", std::process::id()));
    for parser in Parser::ALL {
        let campaign = Campaign {
            parser,
            seed: 2024,
            start: 0,
            runs: 3000,
            allocation_limit: 64 << 20,
            dir: dir.clone(),
        };
        let report = campaign.run().unwrap();
        assert!(report.clean(), "{}: {:?}", parser.name(), report.failures);
        assert_eq!(report.executions, 3000);
        assert!(
            report.accepted > 0 && report.refused > 0,
            "{}: the mutations reach both outcomes: {report:?}",
            parser.name()
        );
        // One input replays alone: the same bytes as within the campaign.
        let alone = Campaign {
            start: 17,
            runs: 1,
            ..campaign.clone()
        };
        assert_eq!(alone.input(17).unwrap(), campaign.input(17).unwrap());
        assert!(alone.run().unwrap().clean());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
