// A typed client of the meshflat API. The types come from the committed OpenAPI document
// (schema.d.ts, written by openapi-typescript: `npm run generate`; a test fails when it
// drifts); the requests go through openapi-fetch. The multipart routes take files and a
// `params` JSON part, which openapi-fetch's types cannot model (a binary part is typed as a
// string): `json`, `svg`, `glb` and `blob` build the form and type the params and the answer
// by the route.
import createClient, { type Client, type ClientOptions, type Middleware } from 'openapi-fetch';
import type { components, paths } from './schema';

export type { components, paths };
export type Schemas = components['schemas'];

/** The routes whose request is a multipart form (files and a `params` JSON part). */
export type FormRoute = {
  [P in keyof paths]: paths[P] extends { post: { requestBody: { content: { 'multipart/form-data': object } } } } ? P : never;
}[keyof paths];

type FormBody<P extends FormRoute> = paths[P]['post']['requestBody']['content']['multipart/form-data'];

/** A route's `params`, as its schema gives them (the fields with a default may be left out). */
export type FormParams<P extends FormRoute> = NonNullable<FormBody<P> extends { params?: infer Q } ? Q : never>;

/** A file to upload: its bytes and its name (the service reads the format from its extension). */
export interface NamedFile {
  blob: Blob;
  name: string;
}

/** A route's file parts by name (`mesh`; `baseline` and `follow_up`; `mask`, ...), required
 * as the route requires them. */
export type FormFiles<P extends FormRoute> = { [K in keyof Omit<FormBody<P>, 'params'>]: NamedFile };

type Responses<P extends FormRoute> = paths[P]['post']['responses'];
type Success<P extends FormRoute> = 200 extends keyof Responses<P> ? Responses<P>[200] : never;
/** The media types a route answers with (application/json, image/svg+xml, model/gltf-binary, ...). */
export type Media<P extends FormRoute> = Success<P> extends { content: infer C } ? keyof C & string : never;
/** A route's JSON answer. */
export type Answer<P extends FormRoute> = Success<P> extends { content: { 'application/json': infer A } } ? A : never;

/** A sample's name, as GET /v1/samples/{name} takes it. */
export type SampleName = paths['/v1/samples/{name}']['get']['parameters']['path']['name'];

/** A refusal: the problem's status, detail and field (`params.zones.0`, say). */
export class Problem extends Error {
  readonly status: number;
  readonly field: string | null;
  readonly problem: Partial<Schemas['ProblemDetails']>;

  constructor(status: number, problem: Partial<Schemas['ProblemDetails']>) {
    super(`${status}: ${problem.detail ?? problem.title ?? 'request failed'}`);
    this.name = 'Problem';
    this.status = status;
    this.field = problem.field ?? null;
    this.problem = problem;
  }
}

/** The multipart body of a form route: each file part by its name, then `params` as JSON. */
export function formData<P extends FormRoute>(files: FormFiles<P>, params: FormParams<P>): FormData {
  const form = new FormData();
  for (const [part, file] of Object.entries(files) as [string, NamedFile | undefined][]) {
    if (file) form.append(part, file.blob, file.name);
  }
  form.append('params', JSON.stringify(params));
  return form;
}

/** The form routes that can answer with media type `M` (the pictures: image/svg+xml). */
export type RouteAnswering<M extends string> = { [P in FormRoute]: M extends Media<P> ? P : never }[FormRoute];

export interface MeshflatOptions extends ClientOptions {
  /** The API key, read at each request (the service's MESHFLAT_API_KEYS); none: no header. */
  apiKey?: () => string | undefined;
}

export interface Meshflat {
  /** openapi-fetch's client, typed by the document's paths, for the JSON routes. */
  client: Client<paths>;
  /** GET /v1/samples: the bundled samples, with their units. */
  samples(): Promise<Schemas['SampleInfo'][]>;
  /** GET /v1/samples/{name}: a sample's file. */
  sample(name: string): Promise<NamedFile>;
  /** POST a form route for its JSON answer, typed by the route. */
  json<P extends FormRoute>(path: P, files: FormFiles<P>, params: FormParams<P>): Promise<Answer<P>>;
  /** POST a form route for its map picture, an SVG document as text. */
  svg<P extends RouteAnswering<'image/svg+xml'>>(path: P, files: FormFiles<P>, params: FormParams<P>): Promise<string>;
  /** POST a form route for its GLB (the region with the map's UVs), as bytes. */
  glb<P extends RouteAnswering<'model/gltf-binary'>>(path: P, files: FormFiles<P>, params: FormParams<P>): Promise<ArrayBuffer>;
  /** POST a form route for any other form of its answer (`accept`: image/png, application/ply, ...). */
  blob<P extends FormRoute>(path: P, files: FormFiles<P>, params: FormParams<P>, accept: Media<P>): Promise<Blob>;
}

// A route's answer, or its problem thrown.
function answered<T>(result: { data?: T; error?: unknown; response: Response }): T {
  if (result.response.ok) return result.data as T;
  const problem = typeof result.error === 'object' && result.error !== null ? result.error : { detail: result.response.statusText };
  throw new Problem(result.response.status, problem as Partial<Schemas['ProblemDetails']>);
}

// openapi-fetch types a POST's body by its path; a form goes as FormData, which its types
// cannot describe, so a form route is called through this looser signature.
type LoosePost = (path: string, init: Record<string, unknown>) => Promise<{ data?: unknown; error?: unknown; response: Response }>;

export function meshflat(options: MeshflatOptions = {}): Meshflat {
  const { apiKey, ...clientOptions } = options;
  const client = createClient<paths>(clientOptions);
  if (apiKey) {
    const key: Middleware = {
      onRequest({ request }) {
        const value = apiKey()?.trim();
        if (value) request.headers.set('X-API-Key', value);
        return request;
      },
    };
    client.use(key);
  }
  const loosePost = client.POST as unknown as LoosePost;
  // A form route's answer as `accept`, read as `parseAs`; or its problem thrown.
  async function post(path: FormRoute, body: FormData, accept: string, parseAs: 'json' | 'text' | 'arrayBuffer' | 'blob') {
    return answered(await loosePost(path, { body, headers: { Accept: accept }, parseAs }));
  }
  return {
    client,
    async samples() {
      return answered(await client.GET('/v1/samples'));
    },
    async sample(name) {
      const path = { name: name as SampleName };
      const blob = answered(await client.GET('/v1/samples/{name}', { params: { path }, parseAs: 'blob' }));
      return { blob, name };
    },
    async json(path, files, params) {
      return (await post(path, formData(files, params), 'application/json', 'json')) as never;
    },
    async svg(path, files, params) {
      return (await post(path, formData(files, params), 'image/svg+xml', 'text')) as string;
    },
    async glb(path, files, params) {
      return (await post(path, formData(files, params), 'model/gltf-binary', 'arrayBuffer')) as ArrayBuffer;
    },
    async blob(path, files, params, accept) {
      return (await post(path, formData(files, params), accept, 'blob')) as Blob;
    },
  };
}
