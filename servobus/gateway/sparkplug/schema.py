"""The Sparkplug B payload classes, built at import from Eclipse Tahu's ``sparkplug_b.proto``.

Decision (docs/gateway.md "Sparkplug B"): no generated ``*_pb2.py`` is committed and protoc is
not needed. The schema file ships unchanged as package data (EPL-2.0, its licence beside it,
``LICENSE-EPL-2.0.html``); :func:`parse_proto` reads the part of the proto2 language that it
uses (package, enums, nested messages, optional/required/repeated fields, oneofs, extension
ranges; options are skipped) into a ``FileDescriptorProto``, and the ``protobuf`` package
(its own descriptor pool) makes the message classes from that. A construct outside that
subset is a :class:`SchemaError`, never skipped silently. The tests compare the descriptor
with protoc's (grpcio-tools) and decode with protoc-generated classes.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

PROTO = "sparkplug_b.proto"
F = descriptor_pb2.FieldDescriptorProto
SCALARS: dict[str, int] = {
    "double": F.TYPE_DOUBLE, "float": F.TYPE_FLOAT, "int64": F.TYPE_INT64,
    "uint64": F.TYPE_UINT64, "int32": F.TYPE_INT32, "fixed64": F.TYPE_FIXED64,
    "fixed32": F.TYPE_FIXED32, "bool": F.TYPE_BOOL, "string": F.TYPE_STRING,
    "bytes": F.TYPE_BYTES, "uint32": F.TYPE_UINT32, "sfixed32": F.TYPE_SFIXED32,
    "sfixed64": F.TYPE_SFIXED64, "sint32": F.TYPE_SINT32, "sint64": F.TYPE_SINT64,
}
LABELS = {"optional": F.LABEL_OPTIONAL, "required": F.LABEL_REQUIRED,
          "repeated": F.LABEL_REPEATED}
#: "to max" in an extension range: field numbers go up to 2**29 - 1 (end is exclusive)
MAX_FIELD_END = 2**29
_TOKEN = re.compile(r'\s+|//[^\n]*|/\*.*?\*/'  # blanks and comments: dropped
                    r'|("(?:[^"\\]|\\.)*")'  # a string
                    r'|([A-Za-z_][\w.]*|-?\d+|[{}=;\[\](),<>])', re.S)


class SchemaError(ValueError):
    """The .proto holds something this reader does not know."""


def tokens(text: str) -> list[str]:
    out: list[str] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise SchemaError(f"unexpected character {text[pos]!r} at offset {pos}")
        if m.group(1) or m.group(2):
            out.append(m.group(1) or m.group(2))
        pos = m.end()
    return out


@dataclass
class _Reader:
    toks: list[str]
    at: int = 0
    #: fields whose type is a message or enum name, resolved once every name is known
    pending: list[tuple[str, Any]] = field(default_factory=list)
    enums: set[str] = field(default_factory=set)
    messages: set[str] = field(default_factory=set)

    def peek(self) -> str:
        if self.at >= len(self.toks):
            raise SchemaError("unexpected end of the schema")
        return self.toks[self.at]

    def take(self, expected: str | None = None) -> str:
        tok = self.peek()
        if expected is not None and tok != expected:
            raise SchemaError(f"expected {expected!r}, found {tok!r} (token {self.at})")
        self.at += 1
        return tok

    def skip_statement(self) -> None:
        """``option ...;`` (and ``[...]`` field options): nothing the classes need."""
        while self.take() != ";":
            pass

    def enum(self, scope: str, out: descriptor_pb2.EnumDescriptorProto) -> None:
        out.name = self.take()
        self.enums.add(f"{scope}.{out.name}")
        self.take("{")
        while self.peek() != "}":
            if self.peek() == "option":
                self.skip_statement()
                continue
            name = self.take()
            self.take("=")
            out.value.add(name=name, number=int(self.take()))
            self.take(";")
        self.take("}")

    def message(self, scope: str, out: descriptor_pb2.DescriptorProto) -> None:
        """Fill ``out`` in place (the fields' type names are set later, on these objects:
        appending a copy would lose them)."""
        out.name = self.take()
        full = f"{scope}.{out.name}"
        self.messages.add(full)
        self.take("{")
        while self.peek() != "}":
            word = self.peek()
            if word == "message":
                self.take()
                self.message(full, out.nested_type.add())
            elif word == "enum":
                self.take()
                self.enum(full, out.enum_type.add())
            elif word == "oneof":
                self.take()
                index = len(out.oneof_decl)
                out.oneof_decl.add(name=self.take())
                self.take("{")
                while self.peek() != "}":
                    self.field(out, full, F.LABEL_OPTIONAL, index)
                self.take("}")
            elif word == "extensions":
                self.take()
                self.extensions(out)
            elif word == "option":
                self.skip_statement()
            elif word in LABELS:
                self.field(out, full, LABELS[self.take()], None)
            else:
                raise SchemaError(f"message {full}: {word!r} is not read by this reader")
        self.take("}")

    def field(self, out: descriptor_pb2.DescriptorProto, scope: str, label: int,
              oneof: int | None) -> None:
        kind, name = self.take(), self.take()
        self.take("=")
        f = out.field.add(name=name, number=int(self.take()), label=label)
        if oneof is not None:
            f.oneof_index = oneof
        if kind in SCALARS:
            f.type = SCALARS[kind]
        else:
            self.pending.append((f"{scope}|{kind}", f))
        if self.peek() == "[":
            raise SchemaError(f"field {scope}.{name}: field options are not read")
        self.take(";")

    def extensions(self, out: descriptor_pb2.DescriptorProto) -> None:
        while True:
            start = int(self.take())
            end = start + 1
            if self.peek() == "to":
                self.take()
                last = self.take()
                end = MAX_FIELD_END if last == "max" else int(last) + 1
            out.extension_range.add(start=start, end=end)
            if self.take() == ";":
                return

    def resolve(self) -> None:
        """Each named type by protobuf's scoping: the innermost enclosing scope first."""
        for key, f in self.pending:
            scope, kind = key.split("|")
            found = self._lookup(scope, kind)
            f.type_name = found
            f.type = F.TYPE_ENUM if found[1:] in self.enums else F.TYPE_MESSAGE

    def _lookup(self, scope: str, kind: str) -> str:
        if kind.startswith("."):
            return kind
        parts = scope.split(".")
        while parts:
            candidate = ".".join([*parts, kind])
            if candidate in self.messages or candidate in self.enums:
                return f".{candidate}"
            parts.pop()
        if kind in self.messages or kind in self.enums:
            return f".{kind}"
        raise SchemaError(f"type {kind!r} (used in {scope}) is not defined")


def parse_proto(text: str, name: str = PROTO) -> descriptor_pb2.FileDescriptorProto:
    """The FileDescriptorProto of a proto2 schema in the subset described above."""
    reader = _Reader(tokens(text))
    out = descriptor_pb2.FileDescriptorProto(name=name)
    package = ""
    while reader.at < len(reader.toks):
        word = reader.take()
        if word == "syntax":
            reader.take("=")
            syntax = reader.take().strip('"')
            if syntax != "proto2":
                raise SchemaError(f"syntax {syntax!r}: only proto2 is read")
            out.syntax = syntax
            reader.take(";")
        elif word == "package":
            package = out.package = reader.take()
            reader.take(";")
        elif word == "option":
            reader.skip_statement()
        elif word == "enum":
            reader.enum(package, out.enum_type.add())
        elif word == "message":
            reader.message(package, out.message_type.add())
        else:
            raise SchemaError(f"{word!r} at the top level is not read by this reader")
    reader.resolve()
    return out


def schema_text() -> str:
    return resources.files(__package__).joinpath(PROTO).read_text(encoding="utf-8")


def _classes() -> tuple[descriptor_pb2.FileDescriptorProto, type[Any]]:
    proto = parse_proto(schema_text())
    pool = descriptor_pool.DescriptorPool()  # our own: no clash with another Tahu module
    pool.Add(proto)
    payload = pool.FindMessageTypeByName(f"{proto.package}.Payload")
    return proto, message_factory.GetMessageClass(payload)


#: The schema as read, and the Payload message class (Payload.Metric, ... as attributes).
DESCRIPTOR, Payload = _classes()
DATA_TYPES: dict[str, int] = {v.name: v.number for v in DESCRIPTOR.enum_type[0].value}
