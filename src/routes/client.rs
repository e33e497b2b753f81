//! The browser client: `GET /` (the page) and `GET /client/{*file}` (its ES modules and CSS,
//! and the vendored three.js under `vendor/three/`, imported by the 3D viewer through the
//! page's import map); `GET /docs`, the API reference rendered by the vendored Swagger UI. The files live under `api/client/` and are embedded in the binary, so
//! the service needs nothing beside itself (no CDN). A file is found by its exact path in the
//! fixed list below, never on the file system, so no request can name anything else. Each
//! response carries a strong ETag (a hash of the file) with `Cache-Control: no-cache`:
//! browsers revalidate and get a 304 while the file is unchanged, and a new build is picked
//! up at once (the modules import each other by plain relative names, so no version can be
//! put in their URLs without a build step).

use crate::problem::Problem;
use crate::state::AppState;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};
use std::sync::OnceLock;

/// One embedded file.
struct Asset {
    name: &'static str,
    content_type: &'static str,
    body: &'static [u8],
}

macro_rules! asset {
    ($name:literal, $ct:expr) => {
        Asset {
            name: $name,
            content_type: $ct,
            body: include_bytes!(concat!("../../api/client/", $name)),
        }
    };
}

const JS: &str = "text/javascript; charset=utf-8";

/// Every file under `api/client/`, by its path there (a test checks the directory tree and
/// this list agree). three.js 0.187.0 is vendored unmodified from its npm package: the two
/// files of its ES module build (`three.module.js` imports `./three.core.js`; this release
/// ships no minified build), the OrbitControls addon and the licence. Swagger UI 5.35.0 (the
/// API reference at `GET /docs`) is vendored unmodified from its npm package swagger-ui-dist:
/// its browser bundle and stylesheet, with its licence, notice and the bundle's third-party
/// licences.
const ASSETS: &[Asset] = &[
    asset!("index.html", "text/html; charset=utf-8"),
    asset!("favicon.svg", "image/svg+xml"),
    asset!("style.css", "text/css; charset=utf-8"),
    asset!("app.js", JS),
    asset!("api.js", JS),
    asset!("editor.js", JS),
    asset!("jsonpos.js", JS),
    asset!("jobs.js", JS),
    asset!("viewer.js", JS),
    asset!("render.js", JS),
    asset!("colormap.js", JS),
    asset!("plots.js", JS),
    asset!("study.js", JS),
    asset!("meshes.js", JS),
    asset!("util.js", JS),
    asset!("viewer3d.js", JS),
    asset!("vendor/three/LICENSE", "text/plain; charset=utf-8"),
    asset!("vendor/three/build/three.module.js", JS),
    asset!("vendor/three/build/three.core.js", JS),
    asset!("vendor/three/examples/jsm/controls/OrbitControls.js", JS),
    asset!("docs.html", "text/html; charset=utf-8"),
    asset!("docs.js", JS),
    asset!("vendor/swagger-ui/LICENSE", "text/plain; charset=utf-8"),
    asset!("vendor/swagger-ui/NOTICE", "text/plain; charset=utf-8"),
    asset!(
        "vendor/swagger-ui/swagger-ui-bundle.js.LICENSE.txt",
        "text/plain; charset=utf-8"
    ),
    asset!("vendor/swagger-ui/swagger-ui-bundle.js", JS),
    asset!(
        "vendor/swagger-ui/swagger-ui.css",
        "text/css; charset=utf-8"
    ),
];

/// ETags of `ASSETS`, in order, computed once.
fn etags() -> &'static [String] {
    static TAGS: OnceLock<Vec<String>> = OnceLock::new();
    TAGS.get_or_init(|| {
        ASSETS
            .iter()
            .map(|a| {
                let d = Sha256::digest(a.body);
                let hex: String = d[..8].iter().map(|b| format!("{b:02x}")).collect();
                format!("\"{hex}\"")
            })
            .collect()
    })
}

fn serve(name: &str, headers: &HeaderMap) -> Result<Response, Problem> {
    let i = ASSETS.iter().position(|a| a.name == name).ok_or_else(|| {
        Problem::not_found(format!(
            "no client file {name:?}; the client is served at GET /"
        ))
    })?;
    let (asset, etag) = (&ASSETS[i], &etags()[i]);
    let not_modified = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.split(',')
                .any(|t| t.trim().trim_start_matches("W/") == etag || t.trim() == "*")
        });
    let mut r = if not_modified {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        let mut r = asset.body.into_response();
        r.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static(asset.content_type),
        );
        r
    };
    let h = r.headers_mut();
    h.insert(header::ETAG, HeaderValue::from_str(etag).expect("hex"));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    Ok(r)
}

/// `GET /`: the client page.
pub async fn index(headers: HeaderMap) -> Result<Response, Problem> {
    serve("index.html", &headers)
}

/// `GET /docs`: the HTTP API reference, api/openapi.yaml rendered in the browser.
pub async fn docs(headers: HeaderMap) -> Result<Response, Problem> {
    serve("docs.html", &headers)
}

/// `GET /docs/`: the reference at its address with a trailing slash, as people type it
/// (308 to `/docs`, so relative links of the page resolve as at `/docs`).
pub async fn docs_slash() -> Response {
    (
        StatusCode::PERMANENT_REDIRECT,
        [(header::LOCATION, HeaderValue::from_static("/docs"))],
    )
        .into_response()
}

/// `GET /favicon.ico`: what browsers ask for by themselves; the client's icon (an SVG).
pub async fn favicon(headers: HeaderMap) -> Result<Response, Problem> {
    serve("favicon.svg", &headers)
}

/// `GET /guide`: the user guide at its folder's address (308 to `/guide/`, so the book's
/// relative links resolve).
pub async fn guide_root() -> Response {
    (
        StatusCode::PERMANENT_REDIRECT,
        [(header::LOCATION, HeaderValue::from_static("/guide/"))],
    )
        .into_response()
}

/// `GET /guide/`: the user guide's first page.
pub async fn guide_index(state: State<AppState>) -> Result<Response, Problem> {
    guide(state, Path(String::new())).await
}

/// `GET /guide/{*file}`: a file of the built user guide (`--guide-dir`, the HTML
/// `mdbook build docs` writes), by its relative path: `..`, absolute paths and links out of
/// the folder are 404; a folder is its `index.html`.
pub async fn guide(
    State(state): State<AppState>,
    Path(file): Path<String>,
) -> Result<Response, Problem> {
    let Some(root) = state.rt.config.guide_dir.clone() else {
        return Err(Problem::not_found(
            "this node serves no user guide: build it with `mdbook build docs` (it is written to target/book) and start the node with --guide-dir target/book; its sources are docs/src in the repository",
        ));
    };
    crate::routes::blocking(move || {
        let missing = || Problem::not_found(format!("the user guide has no page {file:?}"));
        let rel = std::path::Path::new(&file);
        if !rel
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
        {
            return Err(missing());
        }
        let root = root
            .canonicalize()
            .map_err(|e| Problem::internal(format!("--guide-dir {}: {e}", root.display())))?;
        let mut path = root.join(rel);
        if path.is_dir() {
            path = path.join("index.html");
        }
        let path = path.canonicalize().map_err(|_| missing())?;
        if !path.starts_with(&root) || !path.is_file() {
            return Err(missing());
        }
        let body = std::fs::read(&path).map_err(|_| missing())?;
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        let content_type = match ext {
            "html" => "text/html; charset=utf-8",
            "css" => "text/css; charset=utf-8",
            "js" => JS,
            "json" => "application/json",
            "svg" => "image/svg+xml",
            "png" => "image/png",
            "woff2" => "font/woff2",
            "woff" => "font/woff",
            "ttf" => "font/ttf",
            "txt" | "md" => "text/plain; charset=utf-8",
            _ => "application/octet-stream",
        };
        let mut r = body.into_response();
        let h = r.headers_mut();
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
        h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
        h.insert(
            header::X_CONTENT_TYPE_OPTIONS,
            HeaderValue::from_static("nosniff"),
        );
        Ok(r)
    })
    .await
}

/// `GET /client/{*file}`: a module, stylesheet or the page itself, or a vendored file
/// (`vendor/three/...`).
pub async fn file(Path(file): Path<String>, headers: HeaderMap) -> Result<Response, Problem> {
    serve(&file, &headers)
}

#[cfg(test)]
mod tests {
    use super::ASSETS;

    /// The files under `dir`, as paths relative to `root` with `/` separators.
    fn files(root: &std::path::Path, dir: &std::path::Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let path = e.unwrap().path();
            if path.is_dir() {
                files(root, &path, out);
            } else {
                let rel = path.strip_prefix(root).unwrap();
                let parts: Vec<_> = rel.iter().map(|p| p.to_string_lossy()).collect();
                out.push(parts.join("/"));
            }
        }
    }

    /// Every file under api/client/ (subdirectories too) is embedded, and nothing else is
    /// listed.
    #[test]
    fn assets_match_the_directory() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("api/client");
        let mut on_disk = Vec::new();
        files(&dir, &dir, &mut on_disk);
        on_disk.sort();
        let mut listed: Vec<String> = ASSETS.iter().map(|a| a.name.to_string()).collect();
        listed.sort();
        assert_eq!(
            on_disk, listed,
            "api/client/ and ASSETS in client.rs differ"
        );
    }

    #[test]
    fn content_types_follow_extensions() {
        for a in ASSETS {
            let file = a.name.rsplit('/').next().unwrap();
            let want = match file.rsplit('.').next().unwrap() {
                "html" => "text/html",
                "css" => "text/css",
                "js" => "text/javascript",
                "LICENSE" | "NOTICE" | "txt" => "text/plain",
                "svg" => "image/svg+xml",
                _ => panic!("unexpected client file {}", a.name),
            };
            assert!(a.content_type.starts_with(want), "{}", a.name);
        }
    }
}
