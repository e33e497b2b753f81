//! The job store's contract (`service_support::store_contract`) against the embedded SQLite
//! store, each case on a fresh database file (as the service uses it: WAL,
//! `synchronous=FULL`). SQLite's own behaviour (reopening, migrations, its clock) is unit
//! tested in src/store/sqlite/tests.rs.

mod service_support;

use contact_sim::store::sqlite::SqliteStore;
use service_support::store_contract::{self, Fixture};
use service_support::TempDir;

#[test]
fn sqlite_store_contract() {
    let cases = store_contract::run("SQLite", |case| {
        let dir = TempDir::new(&format!("store-{case}"));
        let path = dir.0.join("jobs.sqlite");
        Fixture {
            store: Box::new(SqliteStore::open(&path).unwrap()),
            connect: Box::new(move || {
                // The directory lives as long as the fixture.
                let _dir = &dir;
                Box::new(SqliteStore::open(&path).unwrap())
            }),
        }
    });
    eprintln!("SQLite: {cases} contract cases passed");
}
