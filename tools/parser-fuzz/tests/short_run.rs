//! A short campaign on every reader (a few seconds; the full one is in `docs/input-checks.md`): no
//! panic, no error without the file's name or on more than one line, no allocation over the cap
//! (the process would abort), and the mutations reach both accepted and refused inputs. The
//! committed corpus (`corpus/`) is read as it stands: its seeds are accepted, and each file of
//! `corpus/calib-refused/` is refused naming what its first line says.

use parser_fuzz::seeds::{corpus, corpus_dir};
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

#[test]
fn every_committed_seed_is_accepted_by_its_reader() {
    for parser in Parser::ALL {
        let files = corpus(&corpus_dir(parser)).unwrap();
        assert!(!files.is_empty(), "{}: no committed seed", parser.name());
        for file in files {
            // Either mode of the reader (CSV: strict or repair).
            let outcomes = [0, 1].map(|variant| parser.read(&file, variant));
            assert!(
                outcomes.iter().any(Result::is_ok),
                "{}: {outcomes:?}",
                file.display()
            );
        }
    }
}

#[test]
fn each_implausible_calibration_file_is_refused_naming_its_key() {
    let dir = corpus_dir(Parser::Calib).with_file_name("calib-refused");
    let files = corpus(&dir).unwrap();
    assert!(files.len() >= 9, "{files:?}");
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        let named = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# refused: "))
            .unwrap_or_else(|| panic!("{}: no `# refused: ` line", file.display()));
        let err = Parser::Calib.read(&file, 0).unwrap_err();
        assert!(
            err.contains(file.to_str().unwrap()) && err.contains(named) && !err.contains('\n'),
            "{}: {err}",
            file.display()
        );
    }
}
