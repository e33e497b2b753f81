// GET /docs: the HTTP API reference, api/openapi.yaml (served at /openapi.yaml) rendered by
// Swagger UI, vendored unmodified from its npm package swagger-ui-dist under
// vendor/swagger-ui/ (Apache-2.0, see LICENSE and NOTICE there). The scene schema it
// references is fetched from /scene.schema.json beside it. "Try it out" sends real requests
// to this server; a server with API keys needs "Authorize" with a key first.
/* global SwaggerUIBundle */
window.addEventListener('DOMContentLoaded', () => {
  SwaggerUIBundle({
    url: '/openapi.yaml',
    dom_id: '#api-reference',
    deepLinking: true,
    docExpansion: 'list',
    defaultModelsExpandDepth: 0,
    tryItOutEnabled: false,
  });
});
