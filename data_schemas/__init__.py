"""The JSON Schemas of hydrotact's files, installed as the package data of
`hydrotact._schema_files` (a link to this folder; read them with
`hydrotact._schemas.load_schema`)."""
